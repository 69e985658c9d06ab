//! The file form of a scenario (what serde reads) and its conversion into the typed [`Scenario`].
//!
//! Conversion checks what the types need: finite numbers, coordinates within
//! ±[`crate::limits::MAX_COORDINATE_M`] (before any geometry is computed from them), anchor ids
//! that fit a byte, simple polygons and a valid area. Everything else is checked by [`crate::validate`].

use std::path::Path;

use serde::Deserialize;
use trajgen::{Area, AreaError, Point, Polygon, Waypoint};

use crate::error::{Location, Problem, ScenarioError};
use crate::model::{Anchor, EnuOrigin, Environment, Obstacle, Route, Scenario, Wall};
use crate::settings::{CampaignSettings, GeneratorSettings, Vehicle};

/// A scenario as written in a file, before any check.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScenario {
    #[serde(default)]
    pub name: Option<String>,
    #[serde(default)]
    pub description: Option<String>,
    #[serde(default)]
    pub origin: Option<EnuOrigin>,
    pub fence: Vec<RawPoint>,
    #[serde(default)]
    pub cutouts: Vec<Vec<RawPoint>>,
    pub start_route: Vec<RawRoutePoint>,
    pub recovery_route: Vec<RawRoutePoint>,
    #[serde(default)]
    pub anchors: Vec<RawAnchor>,
    #[serde(default)]
    pub environment: RawEnvironment,
    #[serde(default)]
    pub vehicle: Vehicle,
    #[serde(default)]
    pub generator: GeneratorSettings,
    #[serde(default)]
    pub campaign: CampaignSettings,
}

/// A polygon vertex or wall end.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPoint {
    pub x: f64,
    pub y: f64,
}

/// A route point.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRoutePoint {
    pub x: f64,
    pub y: f64,
    pub speed: f64,
}

/// An anchor, its id still the file's integer.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAnchor {
    pub id: i64,
    pub x: f64,
    pub y: f64,
    pub height: f64,
}

/// The environment section.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(crate) struct RawEnvironment {
    pub obstacles: Vec<RawObstacle>,
    pub walls: Vec<RawWall>,
}

/// An obstacle.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawObstacle {
    pub name: String,
    pub polygon: Vec<RawPoint>,
    #[serde(default)]
    pub illustrative: bool,
}

/// A wall.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawWall {
    pub name: String,
    pub a: RawPoint,
    pub b: RawPoint,
    #[serde(default)]
    pub illustrative: bool,
}

/// Parses TOML text into the file form; syntax and schema errors carry line and column, schema
/// errors also the field path.
pub(crate) fn parse_toml(text: &str, source_name: &str) -> Result<RawScenario, ScenarioError> {
    let deserializer = toml::Deserializer::parse(text).map_err(|e| {
        let location = e.span().map(|s| Location::of_offset(text, s.start));
        ScenarioError::in_source(
            source_name,
            location,
            Problem::TomlSyntax(e.message().trim().to_owned()),
        )
    })?;
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let mut error = ScenarioError::in_source(
            source_name,
            inner.span().map(|s| Location::of_offset(text, s.start)),
            Problem::Schema(inner.message().trim().to_owned()),
        );
        if path != "." {
            error.place.field = Some(path);
        }
        error
    })
}

/// Converts the file form into a [`Scenario`], checking numbers, ids, polygons and the area.
pub(crate) fn build(raw: RawScenario, source_name: &str) -> Result<Scenario, ScenarioError> {
    let err = |field: String, problem| ScenarioError::in_field(source_name, field, problem);
    let name = raw.name.unwrap_or_else(|| stem(source_name));
    let fence = polygon(&raw.fence, "fence").map_err(|(f, p)| err(f, p))?;
    let cutouts = raw
        .cutouts
        .iter()
        .enumerate()
        .map(|(i, c)| polygon(c, &format!("cutouts[{i}]")))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|(f, p)| err(f, p))?;
    let area = Area::new(fence, cutouts).map_err(|e| area_error(source_name, e))?;
    let start_route = route(&raw.start_route, "start_route").map_err(|(f, p)| err(f, p))?;
    let recovery_route =
        route(&raw.recovery_route, "recovery_route").map_err(|(f, p)| err(f, p))?;
    let anchors = anchors(&raw.anchors).map_err(|(f, p)| err(f, p))?;
    let environment = environment(&raw.environment).map_err(|(f, p)| err(f, p))?;
    Ok(Scenario {
        name,
        description: raw.description,
        origin: raw.origin,
        area,
        start_route,
        recovery_route,
        anchors,
        environment,
        vehicle: raw.vehicle,
        generator: raw.generator,
        campaign: raw.campaign,
    })
}

/// A problem in a field: the field path and what is wrong.
type FieldProblem = (String, Problem);

/// The file stem of a source name (`areas/courtyard.toml` → `courtyard`).
fn stem(source_name: &str) -> String {
    Path::new(source_name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A number that must be finite.
fn finite(value: f64, field: impl FnOnce() -> String) -> Result<f64, FieldProblem> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err((field(), Problem::NotFinite))
    }
}

/// A coordinate (or height): finite and within ±[`crate::limits::MAX_COORDINATE_M`], checked
/// before any geometry is computed from it.
fn coordinate(value: f64, field: impl FnOnce() -> String) -> Result<f64, FieldProblem> {
    crate::validate::coordinate(value, &field()).map(|()| value)
}

fn point(p: &RawPoint, field: &str) -> Result<Point, FieldProblem> {
    let x = coordinate(p.x, || format!("{field}.x"))?;
    let y = coordinate(p.y, || format!("{field}.y"))?;
    Ok(Point::new(x, y))
}

fn polygon(vertices: &[RawPoint], field: &str) -> Result<Polygon, FieldProblem> {
    if vertices.len() > crate::MAX_POLYGON_VERTICES {
        return Err((
            field.to_owned(),
            Problem::TooManyVertices {
                count: vertices.len(),
                max: crate::MAX_POLYGON_VERTICES,
            },
        ));
    }
    let points = vertices
        .iter()
        .enumerate()
        .map(|(i, p)| point(p, &format!("{field}[{i}]")))
        .collect::<Result<Vec<_>, _>>()?;
    Polygon::new(points).map_err(|e| (field.to_owned(), Problem::Polygon(e)))
}

fn area_error(source_name: &str, error: AreaError) -> ScenarioError {
    match error {
        AreaError::CutoutOutsideFence { index } => ScenarioError::in_field(
            source_name,
            format!("cutouts[{index}]"),
            Problem::CutoutOutsideFence,
        ),
        AreaError::CutoutsOverlap { first, second } => ScenarioError::in_field(
            source_name,
            format!("cutouts[{second}]"),
            Problem::CutoutsOverlap { other: first },
        ),
    }
}

fn route(points: &[RawRoutePoint], field: &str) -> Result<Route, FieldProblem> {
    let points = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let at = |name: &str| format!("{field}[{i}].{name}");
            Ok(Waypoint::new(
                Point::new(coordinate(p.x, || at("x"))?, coordinate(p.y, || at("y"))?),
                finite(p.speed, || at("speed"))?,
            ))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Route { points })
}

fn anchors(raw: &[RawAnchor]) -> Result<Vec<Anchor>, FieldProblem> {
    raw.iter()
        .enumerate()
        .map(|(i, a)| {
            let at = |name: &str| format!("anchors[{i}].{name}");
            let id =
                u8::try_from(a.id).map_err(|_| (at("id"), Problem::AnchorIdOutOfRange(a.id)))?;
            Ok(Anchor {
                id,
                x: coordinate(a.x, || at("x"))?,
                y: coordinate(a.y, || at("y"))?,
                height: coordinate(a.height, || at("height"))?,
            })
        })
        .collect()
}

fn environment(raw: &RawEnvironment) -> Result<Environment, FieldProblem> {
    let obstacles = raw
        .obstacles
        .iter()
        .enumerate()
        .map(|(i, o)| {
            Ok(Obstacle {
                name: o.name.clone(),
                polygon: polygon(&o.polygon, &format!("environment.obstacles[{i}].polygon"))?,
                illustrative: o.illustrative,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let walls = raw
        .walls
        .iter()
        .enumerate()
        .map(|(i, w)| {
            Ok(Wall {
                name: w.name.clone(),
                a: point(&w.a, &format!("environment.walls[{i}].a"))?,
                b: point(&w.b, &format!("environment.walls[{i}].b"))?,
                illustrative: w.illustrative,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Environment { obstacles, walls })
}
