//! Reading a GeoJSON FeatureCollection into the file form of a scenario.
//!
//! Three steps: each feature's role and geometry ([`gather`]), the coordinate kind and origin
//! ([`decide_crs`], [`decide_origin`]), then the positions in local metres ([`to_raw`]). Every
//! problem names the feature and member it is in.

use serde::Deserialize;
use serde_json::{Map, Value};

use super::{Crs, CrsSource, OriginSource, ReadOptions, VERSION};
use crate::error::{GeoJsonProblem, Problem, Warning, WarningKind};
use crate::geodesy::geodetic_to_enu;
use crate::model::EnuOrigin;
use crate::raw::RawWall;
use crate::raw::{RawAnchor, RawEnvironment, RawObstacle, RawPoint, RawRoutePoint, RawScenario};
use crate::settings::{CampaignSettings, GeneratorSettings, Vehicle};

/// A problem in a field: the field path and what is wrong.
pub(super) type FieldProblem = (String, Problem);

/// The smallest fence, read as metres, that is plausible as a test area (its bounding box's
/// diagonal): the car is 0.5 m wide and turns on a circle of 2 m.
const MIN_LOCAL_FENCE_M: f64 = 2.0;
/// The largest fence, read as longitude and latitude, that is plausible as a test area, metres
/// (generous: a fence of 2–2.7 units is then both, and refused until the kind is given).
const MAX_WGS84_FENCE_M: f64 = 300_000.0;

/// The collection's `drivecheck` member: the format version, the coordinate kind, the origin,
/// and whatever of the scenario is not geometry.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Meta {
    version: u64,
    #[serde(default)]
    crs: Option<String>,
    #[serde(default)]
    origin: Option<EnuOrigin>,
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    description: Option<String>,
    #[serde(default)]
    vehicle: Option<Vehicle>,
    #[serde(default)]
    generator: Option<GeneratorSettings>,
    #[serde(default)]
    campaign: Option<CampaignSettings>,
}

/// A position as written: two numbers (x, y or longitude, latitude) and an optional third.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Pos {
    a: f64,
    b: f64,
    z: Option<f64>,
}

/// A ring or line: its positions (a ring's closing duplicate dropped) and its field path.
#[derive(Debug, Clone)]
struct Line {
    path: String,
    positions: Vec<Pos>,
}

/// A feature's geometry.
enum Geometry {
    Point(Pos),
    LineString(Line),
    /// Exterior ring, then holes.
    Polygon(Vec<Line>),
    MultiPolygon(Vec<Vec<Line>>),
    Other(String),
}

impl Geometry {
    fn name(&self) -> String {
        match self {
            Geometry::Point(_) => "Point".into(),
            Geometry::LineString(_) => "LineString".into(),
            Geometry::Polygon(_) => "Polygon".into(),
            Geometry::MultiPolygon(_) => "MultiPolygon".into(),
            Geometry::Other(name) => name.clone(),
        }
    }
}

/// What a feature is in the scenario (its `drivecheck` property).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Fence,
    Cutout,
    Anchor,
    Route,
    Obstacle,
    Wall,
}

impl Role {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "fence" => Role::Fence,
            "cutout" => Role::Cutout,
            "anchor" => Role::Anchor,
            "route" => Role::Route,
            "obstacle" => Role::Obstacle,
            "wall" => Role::Wall,
            _ => return None,
        })
    }

    fn article(self) -> &'static str {
        match self {
            Role::Fence => "a fence",
            Role::Cutout => "a cutout",
            Role::Anchor => "an anchor",
            Role::Route => "a route",
            Role::Obstacle => "an obstacle",
            Role::Wall => "a wall",
        }
    }
}

/// A route as found.
struct FoundRoute {
    feature: usize,
    line: Line,
    speeds: Vec<f64>,
}

/// An anchor as found: its feature, position, and id and height when given.
struct FoundAnchor {
    feature: usize,
    at: Pos,
    id: Option<i64>,
    height: Option<f64>,
    /// True when it has no `drivecheck` property (a Point is an anchor).
    inferred: bool,
}

/// A named polygon or wall of the environment.
struct FoundObstacle {
    feature: usize,
    name: String,
    illustrative: bool,
    ring: Line,
}

struct FoundWall {
    feature: usize,
    name: String,
    illustrative: bool,
    line: Line,
}

/// Every feature sorted into its part of the scenario, positions still as written.
#[derive(Default)]
struct Gathered {
    /// The fence's feature and its rings (exterior first).
    fence: Option<(usize, Vec<Line>)>,
    /// Polygons without a role: (feature, rings).
    unmarked_polygons: Vec<(usize, Vec<Line>)>,
    /// Cutout features and their exterior ring, in document order.
    cutouts: Vec<(usize, Line)>,
    anchors: Vec<FoundAnchor>,
    start: Option<FoundRoute>,
    recovery: Option<FoundRoute>,
    obstacles: Vec<FoundObstacle>,
    walls: Vec<FoundWall>,
}

/// The GeoJSON read: the scenario's file form, its warnings, how the coordinates were read and
/// which scenario field came from which feature (`fence` → `features[0].geometry`).
pub(super) struct Read {
    pub raw: RawScenario,
    pub warnings: Vec<Warning>,
    pub crs: (Crs, CrsSource),
    pub origin: Option<(EnuOrigin, OriginSource)>,
    pub fields: Vec<(String, String)>,
}

fn schema(field: impl Into<String>, problem: GeoJsonProblem) -> FieldProblem {
    (field.into(), Problem::GeoJson(Box::new(problem)))
}

fn wrong(field: impl Into<String>, expected: &'static str, found: &Value) -> FieldProblem {
    schema(
        field,
        GeoJsonProblem::WrongType {
            expected,
            found: describe(found),
        },
    )
}

/// A JSON value as a person names it: `a string "Polygon"`, `an array`, `null`.
fn describe(value: &Value) -> String {
    match value {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("the boolean {b}"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) if s.chars().count() <= 40 => format!("the string \"{s}\""),
        Value::String(_) => "a long string".into(),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

/// Reads a parsed GeoJSON document; `name` is the scenario's name unless the file gives one.
pub(super) fn read(
    document: &Value,
    name: &str,
    options: &ReadOptions,
) -> Result<Read, FieldProblem> {
    let top = document
        .as_object()
        .ok_or_else(|| wrong("(top level)", "a FeatureCollection object", document))?;
    match top.get("type").and_then(Value::as_str) {
        Some("FeatureCollection") => {}
        _ => {
            let found = top.get("type").unwrap_or(&Value::Null);
            return Err(wrong("type", "\"FeatureCollection\"", found));
        }
    }
    let meta = meta(top)?;
    let file_crs = file_crs(top, &meta)?;
    let features = match top.get("features") {
        Some(Value::Array(features)) => features,
        Some(other) => return Err(wrong("features", "an array of features", other)),
        None => return Err(wrong("features", "an array of features", &Value::Null)),
    };
    let mut warnings = Vec::new();
    let mut gathered = gather(features)?;
    infer_polygons(&mut gathered, &mut warnings)?;
    let fence = gathered.fence.as_ref().ok_or_else(|| {
        schema(
            "features",
            GeoJsonProblem::Missing {
                role: "fence",
                how: "draw it as a Polygon (with properties {\"drivecheck\": \"fence\"}, or as the \
                      largest polygon)",
            },
        )
    })?;
    let crs = decide_crs(file_crs, options.crs, &fence.1[0], &gathered)?;
    let origin = decide_origin(crs.0, options.origin, meta.origin, &fence.1[0]);
    if let Some((o, OriginSource::FirstVertex)) = origin {
        warnings.push(warning(
            "drivecheck.origin",
            WarningKind::OriginFromFirstVertex {
                lat: o.lat,
                lon: o.lon,
            },
        ));
    }
    let project = Projection {
        crs: crs.0,
        origin: origin.map(|(o, _)| o),
    };
    let (raw, fields) = to_raw(gathered, meta, name, &project, &mut warnings)?;
    Ok(Read {
        raw,
        warnings,
        crs,
        origin,
        fields,
    })
}

fn warning(field: impl Into<String>, kind: WarningKind) -> Warning {
    Warning {
        source_name: String::new(),
        field: field.into(),
        kind,
    }
}

/// The collection's `drivecheck` member, checked (absent: the defaults of every setting).
fn meta(top: &Map<String, Value>) -> Result<Meta, FieldProblem> {
    let Some(value) = top.get("drivecheck") else {
        return Ok(Meta::default());
    };
    let meta: Meta = serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let field = if path == "." {
            "drivecheck".to_owned()
        } else {
            format!("drivecheck.{path}")
        };
        (field, Problem::Schema(e.into_inner().to_string()))
    })?;
    if meta.version > VERSION {
        return Err(schema(
            "drivecheck.version",
            GeoJsonProblem::NewerVersion {
                found: meta.version,
                supported: VERSION,
            },
        ));
    }
    Ok(meta)
}

/// The coordinate kind the file states: the `drivecheck` member's `crs`, else a legacy `crs`
/// member (GeoJSON 2008, as older QGIS writes it).
fn file_crs(top: &Map<String, Value>, meta: &Meta) -> Result<Option<Crs>, FieldProblem> {
    if let Some(crs) = &meta.crs {
        return Crs::parse(crs).map(Some).ok_or_else(|| {
            (
                "drivecheck.crs".to_owned(),
                Problem::Schema(format!(
                    "`{crs}` is not a coordinate kind: expected \"{}\" or \"{}\"",
                    super::CRS_LOCAL,
                    super::CRS_WGS84
                )),
            )
        });
    }
    let Some(legacy) = top.get("crs") else {
        return Ok(None);
    };
    let name = legacy
        .pointer("/properties/name")
        .and_then(Value::as_str)
        .ok_or_else(|| wrong("crs", "a named CRS ({\"type\": \"name\", …})", legacy))?;
    let upper = name.to_ascii_uppercase();
    if upper.ends_with("CRS84") || upper.ends_with("EPSG::4326") || upper.ends_with("EPSG:4326") {
        Ok(Some(Crs::Wgs84))
    } else if name == super::CRS_LOCAL_NAME {
        Ok(Some(Crs::Local))
    } else {
        Err(schema(
            "crs.properties.name",
            GeoJsonProblem::UnsupportedCrs(name.to_owned()),
        ))
    }
}

/// Sorts the features by role; a feature without a `drivecheck` property is kept as an unmarked
/// polygon or an anchor (a Point), refused otherwise.
fn gather(features: &[Value]) -> Result<Gathered, FieldProblem> {
    let mut gathered = Gathered::default();
    for (index, feature) in features.iter().enumerate() {
        let at = format!("features[{index}]");
        let object = feature
            .as_object()
            .ok_or_else(|| wrong(at.clone(), "a Feature object", feature))?;
        match object.get("type").and_then(Value::as_str) {
            Some("Feature") => {}
            _ => {
                let found = object.get("type").unwrap_or(&Value::Null);
                return Err(wrong(format!("{at}.type"), "\"Feature\"", found));
            }
        }
        let empty = Map::new();
        let properties = match object.get("properties") {
            None | Some(Value::Null) => &empty,
            Some(Value::Object(p)) => p,
            Some(other) => return Err(wrong(format!("{at}.properties"), "an object", other)),
        };
        let role = match properties.get("drivecheck") {
            None | Some(Value::Null) => None,
            Some(Value::String(role)) => Some(Role::parse(role).ok_or_else(|| {
                schema(
                    format!("{at}.properties.drivecheck"),
                    GeoJsonProblem::UnknownRole(role.clone()),
                )
            })?),
            Some(other) => {
                return Err(wrong(
                    format!("{at}.properties.drivecheck"),
                    "a string",
                    other,
                ));
            }
        };
        let geometry = match object.get("geometry") {
            None | Some(Value::Null) if role.is_none() => continue,
            None => return Err(wrong(format!("{at}.geometry"), "a geometry", &Value::Null)),
            Some(g) => geometry(g, &format!("{at}.geometry"))?,
        };
        let feature = Found {
            index,
            at: &at,
            properties,
            geometry,
        };
        sort(&mut gathered, role, feature)?;
    }
    Ok(gathered)
}

/// One feature, its geometry read.
struct Found<'a> {
    index: usize,
    at: &'a str,
    properties: &'a Map<String, Value>,
    geometry: Geometry,
}

impl Found<'_> {
    fn cannot_be(&self, role: Role) -> FieldProblem {
        schema(
            format!("{}.geometry", self.at),
            GeoJsonProblem::CannotBe {
                geometry: self.geometry.name(),
                role: role.article(),
            },
        )
    }

    fn property(&self, key: &str) -> Option<&Value> {
        self.properties.get(key).filter(|v| !v.is_null())
    }

    fn field(&self, key: &str) -> String {
        format!("{}.properties.{key}", self.at)
    }

    /// Whether the polygon was drawn clockwise (`"drawn": "clockwise"`): drivecheck's writer
    /// then wrote its exterior ring backwards, by RFC 7946's right-hand rule.
    fn drawn_clockwise(&self) -> Result<bool, FieldProblem> {
        match self.property("drawn") {
            None => Ok(false),
            Some(Value::String(s)) if s == "clockwise" => Ok(true),
            Some(Value::String(s)) if s == "counterclockwise" => Ok(false),
            Some(other) => Err(wrong(
                self.field("drawn"),
                "\"clockwise\" or \"counterclockwise\"",
                other,
            )),
        }
    }

    /// The polygon's rings, or one polygon of a MultiPolygon of one.
    fn polygon(self, role: Role) -> Result<Vec<Line>, FieldProblem> {
        match self.geometry {
            Geometry::Polygon(rings) => Ok(rings),
            Geometry::MultiPolygon(mut parts) if parts.len() == 1 => Ok(parts.remove(0)),
            _ => Err(self.cannot_be(role)),
        }
    }

    /// A polygon without holes: its exterior ring.
    fn simple_polygon(self, role: Role) -> Result<Line, FieldProblem> {
        let at = format!("{}.geometry", self.at);
        let mut rings = self.polygon(role)?;
        if rings.len() > 1 {
            return Err(schema(
                at,
                GeoJsonProblem::CannotBe {
                    geometry: "Polygon with holes".into(),
                    role: role.article(),
                },
            ));
        }
        Ok(rings.remove(0))
    }

    fn name(&self) -> Result<String, FieldProblem> {
        match self.property("name") {
            Some(Value::String(name)) => Ok(name.clone()),
            Some(other) => Err(wrong(self.field("name"), "a string", other)),
            None => Err(wrong(
                self.field("name"),
                "a string (its name)",
                &Value::Null,
            )),
        }
    }

    fn illustrative(&self) -> Result<bool, FieldProblem> {
        match self.property("illustrative") {
            None => Ok(false),
            Some(Value::Bool(b)) => Ok(*b),
            Some(other) => Err(wrong(self.field("illustrative"), "true or false", other)),
        }
    }

    fn number(&self, key: &str) -> Result<Option<f64>, FieldProblem> {
        match self.property(key) {
            None => Ok(None),
            Some(Value::Number(n)) => Ok(n.as_f64()),
            Some(other) => Err(wrong(self.field(key), "a number", other)),
        }
    }
}

fn sort(gathered: &mut Gathered, role: Option<Role>, found: Found<'_>) -> Result<(), FieldProblem> {
    let index = found.index;
    match role {
        None => match found.geometry {
            Geometry::Polygon(_) | Geometry::MultiPolygon(_) => {
                let rings = match found.geometry {
                    Geometry::MultiPolygon(parts) => parts,
                    Geometry::Polygon(rings) => vec![rings],
                    _ => Vec::new(),
                };
                for part in rings {
                    gathered.unmarked_polygons.push((index, part));
                }
            }
            Geometry::Point(_) => gathered.anchors.push(anchor(&found, true)?),
            _ => {
                return Err(schema(
                    format!("{}.properties", found.at),
                    GeoJsonProblem::Missing {
                        role: "`drivecheck` property",
                        how: "only polygons (the fence, cutouts) and points (anchors) can go \
                              without one; mark a route {\"drivecheck\": \"route\", \"route\": \
                              \"start\", \"speed\": 1.0}, a wall {\"drivecheck\": \"wall\"}",
                    },
                ));
            }
        },
        Some(Role::Fence) => {
            if let Some((first, _)) = gathered.fence {
                return Err(duplicate(&found, "fence", first));
            }
            let clockwise = found.drawn_clockwise()?;
            let mut rings = found.polygon(Role::Fence)?;
            rings[0] = as_drawn(rings[0].clone(), clockwise);
            gathered.fence = Some((index, rings));
        }
        Some(Role::Cutout) => {
            let clockwise = found.drawn_clockwise()?;
            let ring = as_drawn(found.simple_polygon(Role::Cutout)?, clockwise);
            gathered.cutouts.push((index, ring));
        }
        Some(Role::Anchor) => {
            if !matches!(found.geometry, Geometry::Point(_)) {
                return Err(found.cannot_be(Role::Anchor));
            }
            gathered.anchors.push(anchor(&found, false)?);
        }
        Some(Role::Route) => route(gathered, found)?,
        Some(Role::Obstacle) => {
            let (name, illustrative) = (found.name()?, found.illustrative()?);
            let clockwise = found.drawn_clockwise()?;
            let ring = as_drawn(found.simple_polygon(Role::Obstacle)?, clockwise);
            gathered.obstacles.push(FoundObstacle {
                feature: index,
                name,
                illustrative,
                ring,
            });
        }
        Some(Role::Wall) => {
            let (name, illustrative) = (found.name()?, found.illustrative()?);
            let Geometry::LineString(line) = found.geometry else {
                return Err(found.cannot_be(Role::Wall));
            };
            if line.positions.len() != 2 {
                return Err(schema(
                    line.path,
                    GeoJsonProblem::WallPoints(line.positions.len()),
                ));
            }
            gathered.walls.push(FoundWall {
                feature: index,
                name,
                illustrative,
                line,
            });
        }
    }
    Ok(())
}

fn duplicate(found: &Found<'_>, role: &'static str, first: usize) -> FieldProblem {
    schema(
        format!("{}.properties.drivecheck", found.at),
        GeoJsonProblem::Duplicate { role, first },
    )
}

fn anchor(found: &Found<'_>, inferred: bool) -> Result<FoundAnchor, FieldProblem> {
    let Geometry::Point(at) = found.geometry else {
        return Err(found.cannot_be(Role::Anchor));
    };
    let id = match found.property("id") {
        None => None,
        Some(value) => Some(whole(value).ok_or_else(|| match value {
            Value::Number(_) | Value::String(_) => schema(
                found.field("id"),
                GeoJsonProblem::NotWhole(value.to_string().trim_matches('"').to_owned()),
            ),
            other => wrong(found.field("id"), "a whole number", other),
        })?),
    };
    Ok(FoundAnchor {
        feature: found.index,
        at,
        id,
        height: found.number("height")?,
        inferred,
    })
}

/// A whole number written as a JSON number (`7`, `7.0`) or a string (`"7"`, as a text
/// attribute of QGIS is written).
fn whole(value: &Value) -> Option<i64> {
    match value {
        Value::Number(n) => n.as_i64().or_else(|| {
            n.as_f64()
                .filter(|x| x.fract() == 0.0 && x.abs() < 1e15)
                .map(|x| x as i64)
        }),
        Value::String(s) => s.trim().parse().ok(),
        _ => None,
    }
}

fn route(gathered: &mut Gathered, found: Found<'_>) -> Result<(), FieldProblem> {
    let which = match found.property("route") {
        Some(Value::String(which)) => which.clone(),
        Some(other) => {
            return Err(wrong(
                found.field("route"),
                "\"start\" or \"recovery\"",
                other,
            ));
        }
        None => {
            return Err(wrong(
                found.field("route"),
                "\"start\" or \"recovery\"",
                &Value::Null,
            ));
        }
    };
    let slot = match which.as_str() {
        "start" => &mut gathered.start,
        "recovery" => &mut gathered.recovery,
        _ => {
            return Err(schema(
                found.field("route"),
                GeoJsonProblem::UnknownRoute(which),
            ));
        }
    };
    if let Some(first) = slot {
        let role = if which == "start" {
            "start route"
        } else {
            "recovery route"
        };
        return Err(duplicate(&found, role, first.feature));
    }
    let speeds = speeds(&found)?;
    let speeds_field = found.field("speeds");
    let Geometry::LineString(line) = found.geometry else {
        return Err(found.cannot_be(Role::Route));
    };
    let speeds = match speeds {
        Speeds::Each(speeds) if speeds.len() != line.positions.len() => {
            return Err(schema(
                speeds_field,
                GeoJsonProblem::SpeedsLength {
                    speeds: speeds.len(),
                    points: line.positions.len(),
                },
            ));
        }
        Speeds::Each(speeds) => speeds,
        Speeds::All(speed) => vec![speed; line.positions.len()],
    };
    *slot = Some(FoundRoute {
        feature: found.index,
        line,
        speeds,
    });
    Ok(())
}

/// A route's speeds: one for every point, or one each.
enum Speeds {
    All(f64),
    Each(Vec<f64>),
}

fn speeds(found: &Found<'_>) -> Result<Speeds, FieldProblem> {
    if let Some(value) = found.property("speeds") {
        let list = value
            .as_array()
            .ok_or_else(|| wrong(found.field("speeds"), "an array of numbers (m/s)", value))?;
        let speeds = list
            .iter()
            .enumerate()
            .map(|(i, v)| {
                v.as_f64()
                    .ok_or_else(|| wrong(format!("{}[{i}]", found.field("speeds")), "a number", v))
            })
            .collect::<Result<_, _>>()?;
        return Ok(Speeds::Each(speeds));
    }
    match found.number("speed")? {
        Some(speed) => Ok(Speeds::All(speed)),
        None => Err(schema(
            format!("{}.properties", found.at),
            GeoJsonProblem::NoSpeed,
        )),
    }
}

/// Reads a geometry object at field path `at`.
fn geometry(value: &Value, at: &str) -> Result<Geometry, FieldProblem> {
    let object = value
        .as_object()
        .ok_or_else(|| wrong(at, "a geometry object", value))?;
    let kind = match object.get("type") {
        Some(Value::String(kind)) => kind.as_str(),
        other => {
            return Err(wrong(
                format!("{at}.type"),
                "a geometry type",
                other.unwrap_or(&Value::Null),
            ));
        }
    };
    let coordinates = || {
        object
            .get("coordinates")
            .ok_or_else(|| wrong(format!("{at}.coordinates"), "coordinates", &Value::Null))
    };
    let path = format!("{at}.coordinates");
    Ok(match kind {
        "Point" => Geometry::Point(position(coordinates()?, &path)?),
        "LineString" => Geometry::LineString(line(coordinates()?, path, false)?),
        "Polygon" => Geometry::Polygon(rings(coordinates()?, &path)?),
        "MultiPolygon" => {
            let parts = array(coordinates()?, &path)?;
            Geometry::MultiPolygon(
                parts
                    .iter()
                    .enumerate()
                    .map(|(i, part)| rings(part, &format!("{path}[{i}]")))
                    .collect::<Result<_, _>>()?,
            )
        }
        other => Geometry::Other(other.to_owned()),
    })
}

fn array<'a>(value: &'a Value, at: &str) -> Result<&'a Vec<Value>, FieldProblem> {
    value.as_array().ok_or_else(|| wrong(at, "an array", value))
}

fn position(value: &Value, at: &str) -> Result<Pos, FieldProblem> {
    let bad = || schema(at, GeoJsonProblem::BadPosition);
    let numbers = value.as_array().ok_or_else(bad)?;
    let number = |i: usize| {
        numbers
            .get(i)
            .map(|v| v.as_f64().ok_or_else(bad))
            .transpose()
    };
    match (number(0)?, number(1)?) {
        (Some(a), Some(b)) if numbers.len() <= 3 => Ok(Pos {
            a,
            b,
            z: number(2)?,
        }),
        _ => Err(bad()),
    }
}

/// A LineString's or ring's positions; a ring's closing duplicate (last = first) is dropped.
fn line(value: &Value, path: String, ring: bool) -> Result<Line, FieldProblem> {
    let mut positions = array(value, &path)?
        .iter()
        .enumerate()
        .map(|(i, v)| position(v, &format!("{path}[{i}]")))
        .collect::<Result<Vec<_>, _>>()?;
    if ring && positions.len() > 1 && positions.first() == positions.last() {
        positions.pop();
    }
    Ok(Line { path, positions })
}

/// The order a ring written by the right-hand rule was drawn in, when it was drawn clockwise:
/// from the first vertex backwards, as the writer reversed it.
fn as_drawn(mut ring: Line, clockwise: bool) -> Line {
    if clockwise && ring.positions.len() > 1 {
        ring.positions[1..].reverse();
    }
    ring
}

/// A polygon's rings: at least the exterior one.
fn rings(value: &Value, at: &str) -> Result<Vec<Line>, FieldProblem> {
    let list = array(value, at)?;
    if list.is_empty() {
        return Err(wrong(at, "at least one ring", value));
    }
    list.iter()
        .enumerate()
        .map(|(i, ring)| line(ring, format!("{at}[{i}]"), true))
        .collect()
}

/// Gives unmarked polygons their role: the largest is the fence when no feature is marked so,
/// the others are cutouts; says so in warnings.
fn infer_polygons(
    gathered: &mut Gathered,
    warnings: &mut Vec<Warning>,
) -> Result<(), FieldProblem> {
    let mut polygons = std::mem::take(&mut gathered.unmarked_polygons);
    if gathered.fence.is_none() && !polygons.is_empty() {
        let largest = (0..polygons.len())
            .max_by(|&i, &j| ring_area(&polygons[i].1[0]).total_cmp(&ring_area(&polygons[j].1[0])))
            .unwrap_or(0);
        let (feature, rings) = polygons.remove(largest);
        warnings.push(warning(
            format!("features[{feature}]"),
            WarningKind::RoleInferred {
                role: "the fence",
                why: "the largest polygon; its holes are cutouts",
            },
        ));
        gathered.fence = Some((feature, rings));
    }
    for (feature, mut rings) in polygons {
        if rings.len() > 1 {
            return Err(schema(
                rings[1].path.clone(),
                GeoJsonProblem::CannotBe {
                    geometry: "Polygon with holes".into(),
                    role: "a cutout",
                },
            ));
        }
        warnings.push(warning(
            format!("features[{feature}]"),
            WarningKind::RoleInferred {
                role: "a cutout",
                why: "a polygon other than the fence",
            },
        ));
        gathered.cutouts.push((feature, rings.remove(0)));
    }
    gathered.cutouts.sort_by_key(|(feature, _)| *feature);
    Ok(())
}

/// The absolute area of a ring in its own units (shoelace).
fn ring_area(ring: &Line) -> f64 {
    let p = &ring.positions;
    let twice: f64 = (0..p.len())
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            a.a * b.b - b.a * a.b
        })
        .sum();
    (twice / 2.0).abs()
}

/// Every position of the gathered features.
fn all_positions(g: &Gathered) -> impl Iterator<Item = Pos> + '_ {
    let rings = g.fence.iter().flat_map(|(_, rings)| rings.iter());
    let lines = rings
        .chain(g.cutouts.iter().map(|(_, ring)| ring))
        .chain(g.start.iter().map(|r| &r.line))
        .chain(g.recovery.iter().map(|r| &r.line))
        .chain(g.obstacles.iter().map(|o| &o.ring))
        .chain(g.walls.iter().map(|w| &w.line));
    lines
        .flat_map(|l| l.positions.iter().copied())
        .chain(g.anchors.iter().map(|a| a.at))
}

/// The coordinate kind: the file's marker, else the command line's, else inferred from the
/// numbers (longitude/latitude when they all fit and the fence would be absurdly small in
/// metres; refused when both readings are plausible).
fn decide_crs(
    file: Option<Crs>,
    asked: Option<Crs>,
    fence: &Line,
    gathered: &Gathered,
) -> Result<(Crs, CrsSource), FieldProblem> {
    match (file, asked) {
        (Some(file), Some(asked)) if file != asked => {
            return Err(schema(
                "drivecheck.crs",
                GeoJsonProblem::CrsConflict {
                    file: file.describe(),
                    asked: asked.describe(),
                },
            ));
        }
        (Some(file), _) => return Ok((file, CrsSource::File)),
        (None, Some(asked)) => return Ok((asked, CrsSource::Asked)),
        (None, None) => {}
    }
    let lon_lat = all_positions(gathered)
        .all(|p| (-180.0..=180.0).contains(&p.a) && (-90.0..=90.0).contains(&p.b));
    let local_m = diagonal(fence.positions.iter().map(|p| (p.a, p.b)));
    if !lon_lat {
        return Ok((Crs::Local, CrsSource::Inferred));
    }
    // An empty ring has no first vertex to take as the origin; the fence's own check refuses it.
    let Some(&first) = fence.positions.first() else {
        return Ok((Crs::Local, CrsSource::Inferred));
    };
    let origin = EnuOrigin {
        lat: first.b,
        lon: first.a,
        height: 0.0,
    };
    let wgs84_m = diagonal(fence.positions.iter().map(|p| {
        let [e, n, _] = geodetic_to_enu(&origin, p.b, p.a, 0.0);
        (e, n)
    }));
    let local = local_m >= MIN_LOCAL_FENCE_M;
    let wgs84 = wgs84_m <= MAX_WGS84_FENCE_M;
    match (local, wgs84) {
        (true, true) => Err(schema(
            "drivecheck.crs",
            GeoJsonProblem::AmbiguousCrs { wgs84_m, local_m },
        )),
        (false, true) => Ok((Crs::Wgs84, CrsSource::Inferred)),
        _ => Ok((Crs::Local, CrsSource::Inferred)),
    }
}

/// The diagonal of the bounding box of points.
fn diagonal(points: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut lo, mut hi) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for (x, y) in points {
        lo = (lo.0.min(x), lo.1.min(y));
        hi = (hi.0.max(x), hi.1.max(y));
    }
    (hi.0 - lo.0).hypot(hi.1 - lo.1)
}

/// The origin: the command line's, else the file's, else (longitude/latitude only) the fence's
/// first vertex.
fn decide_origin(
    crs: Crs,
    asked: Option<EnuOrigin>,
    file: Option<EnuOrigin>,
    fence: &Line,
) -> Option<(EnuOrigin, OriginSource)> {
    if let Some(origin) = asked {
        return Some((origin, OriginSource::Asked));
    }
    if let Some(origin) = file {
        return Some((origin, OriginSource::File));
    }
    let first = fence.positions.first()?;
    (crs == Crs::Wgs84).then(|| {
        let origin = EnuOrigin {
            lat: first.b,
            lon: first.a,
            height: first.z.unwrap_or(0.0),
        };
        (origin, OriginSource::FirstVertex)
    })
}

/// How positions become local metres.
struct Projection {
    crs: Crs,
    origin: Option<EnuOrigin>,
}

impl Projection {
    fn point(&self, p: Pos, at: &str) -> Result<RawPoint, FieldProblem> {
        match (self.crs, &self.origin) {
            (Crs::Wgs84, Some(origin)) => {
                let in_range = (-180.0..=180.0).contains(&p.a) && (-90.0..=90.0).contains(&p.b);
                if !in_range {
                    return Err(schema(at, GeoJsonProblem::NotLonLat { lon: p.a, lat: p.b }));
                }
                let [x, y, _] = geodetic_to_enu(origin, p.b, p.a, origin.height);
                Ok(RawPoint { x, y })
            }
            _ => Ok(RawPoint { x: p.a, y: p.b }),
        }
    }

    fn line(&self, line: &Line) -> Result<Vec<RawPoint>, FieldProblem> {
        line.positions
            .iter()
            .enumerate()
            .map(|(i, &p)| self.point(p, &format!("{}[{i}]", line.path)))
            .collect()
    }
}

/// The scenario's file form from the gathered features, and which field came from which feature.
fn to_raw(
    g: Gathered,
    meta: Meta,
    name: &str,
    project: &Projection,
    warnings: &mut Vec<Warning>,
) -> Result<(RawScenario, Vec<(String, String)>), FieldProblem> {
    let mut fields = Vec::new();
    let no_rings = Vec::new();
    let fence_rings = g.fence.as_ref().map_or(&no_rings, |(_, rings)| rings);
    let Some(exterior) = fence_rings.first() else {
        return Err(schema(
            "features",
            GeoJsonProblem::Missing {
                role: "fence",
                how: "",
            },
        ));
    };
    let fence = project.line(exterior)?;
    fields.push(("fence".to_owned(), exterior.path.clone()));
    let mut cutouts = Vec::new();
    for hole in &fence_rings[1..] {
        fields.push((format!("cutouts[{}]", cutouts.len()), hole.path.clone()));
        cutouts.push(project.line(hole)?);
    }
    for (_, ring) in &g.cutouts {
        fields.push((format!("cutouts[{}]", cutouts.len()), ring.path.clone()));
        cutouts.push(project.line(ring)?);
    }
    let start_route = raw_route(g.start.as_ref(), "start", project)?;
    let recovery_route = raw_route(g.recovery.as_ref(), "recovery", project)?;
    for (field, route) in [("start_route", &g.start), ("recovery_route", &g.recovery)] {
        if let Some(route) = route {
            fields.push((field.to_owned(), route.line.path.clone()));
        }
    }
    let anchors = raw_anchors(&g.anchors, project, warnings, &mut fields)?;
    let environment = raw_environment(&g, project, &mut fields)?;
    fields.push(("origin".to_owned(), "drivecheck.origin".to_owned()));
    for key in ["name", "description", "vehicle", "generator", "campaign"] {
        fields.push((key.to_owned(), format!("drivecheck.{key}")));
    }
    let raw = RawScenario {
        name: Some(meta.name.unwrap_or_else(|| name.to_owned())),
        description: meta.description,
        origin: project.origin,
        fence,
        cutouts,
        start_route,
        recovery_route,
        anchors,
        environment,
        vehicle: meta.vehicle.unwrap_or_default(),
        generator: meta.generator.unwrap_or_default(),
        campaign: meta.campaign.unwrap_or_default(),
    };
    Ok((raw, fields))
}

fn raw_route(
    route: Option<&FoundRoute>,
    which: &'static str,
    project: &Projection,
) -> Result<Vec<RawRoutePoint>, FieldProblem> {
    let route = route.ok_or_else(|| {
        schema(
            "features",
            GeoJsonProblem::Missing {
                role: if which == "start" {
                    "start route"
                } else {
                    "recovery route"
                },
                how: "draw it as a LineString with properties {\"drivecheck\": \"route\", \
                      \"route\": \"start\" or \"recovery\", \"speed\": METRES_PER_SECOND}",
            },
        )
    })?;
    let points = project.line(&route.line)?;
    Ok(points
        .iter()
        .zip(&route.speeds)
        .map(|(p, &speed)| RawRoutePoint {
            x: p.x,
            y: p.y,
            speed,
        })
        .collect())
}

fn raw_anchors(
    found: &[FoundAnchor],
    project: &Projection,
    warnings: &mut Vec<Warning>,
    fields: &mut Vec<(String, String)>,
) -> Result<Vec<RawAnchor>, FieldProblem> {
    let mut used: Vec<i64> = found.iter().filter_map(|a| a.id).collect();
    let mut anchors = Vec::new();
    for (i, anchor) in found.iter().enumerate() {
        let at = format!("features[{}]", anchor.feature);
        fields.push((format!("anchors[{i}]"), at.clone()));
        if anchor.inferred {
            warnings.push(warning(
                at.clone(),
                WarningKind::RoleInferred {
                    role: "an anchor",
                    why: "a point",
                },
            ));
        }
        let id = match anchor.id {
            Some(id) => id,
            None => {
                let free = (1..=255).chain([0]).find(|id| !used.contains(id));
                let id =
                    free.ok_or(("features".to_owned(), Problem::TooManyAnchors(found.len())))?;
                used.push(id);
                let id_u8 = u8::try_from(id).unwrap_or(0);
                warnings.push(warning(
                    at.clone(),
                    WarningKind::AnchorNumbered { id: id_u8 },
                ));
                id
            }
        };
        if anchor.height.is_none() {
            warnings.push(warning(at.clone(), WarningKind::AnchorHeightAssumed));
        }
        let p = project.point(anchor.at, &format!("{at}.geometry.coordinates"))?;
        anchors.push(RawAnchor {
            id,
            x: p.x,
            y: p.y,
            height: anchor.height.unwrap_or(0.0),
        });
    }
    Ok(anchors)
}

fn raw_environment(
    g: &Gathered,
    project: &Projection,
    fields: &mut Vec<(String, String)>,
) -> Result<RawEnvironment, FieldProblem> {
    let mut environment = RawEnvironment::default();
    for (i, o) in g.obstacles.iter().enumerate() {
        fields.push((
            format!("environment.obstacles[{i}]"),
            format!("features[{}]", o.feature),
        ));
        environment.obstacles.push(RawObstacle {
            name: o.name.clone(),
            polygon: project.line(&o.ring)?,
            illustrative: o.illustrative,
        });
    }
    for (i, w) in g.walls.iter().enumerate() {
        fields.push((
            format!("environment.walls[{i}]"),
            format!("features[{}]", w.feature),
        ));
        let ends = project.line(&w.line)?;
        environment.walls.push(RawWall {
            name: w.name.clone(),
            a: ends[0],
            b: ends[1],
            illustrative: w.illustrative,
        });
    }
    Ok(environment)
}
