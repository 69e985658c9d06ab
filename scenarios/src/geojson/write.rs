//! Writing a scenario as a GeoJSON FeatureCollection (the schema of `docs/geojson.md`).

use serde_json::{Map, Value, json};
use trajgen::Point;

use super::{Crs, GeoJsonWriteError, VERSION};
use crate::geodesy::enu_to_geodetic;
use crate::model::{EnuOrigin, Route, Scenario};

/// How to write a scenario as GeoJSON.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WriteOptions {
    /// The coordinate kind; `None`: WGS84 longitude/latitude when there is an origin (given or
    /// the scenario's), local metres otherwise.
    pub crs: Option<Crs>,
    /// The local frame's origin on the globe, in place of the scenario's (written as the
    /// collection's origin, so that the file reads back with it).
    pub origin: Option<EnuOrigin>,
}

/// The scenario as a GeoJSON FeatureCollection: one feature a line, the fence first, then the
/// cutouts, the start and recovery routes, the anchors, obstacles and walls. In local metres it
/// reads back ([`super::from_geojson_str`]) to the same scenario and hash; in longitude/latitude
/// to within a micrometre.
pub fn to_geojson(s: &Scenario, options: &WriteOptions) -> Result<String, GeoJsonWriteError> {
    let origin = options.origin.or(s.origin);
    let crs = options.crs.unwrap_or(if origin.is_some() {
        Crs::Wgs84
    } else {
        Crs::Local
    });
    let place = match (crs, origin) {
        (Crs::Wgs84, None) => return Err(GeoJsonWriteError::NoOrigin),
        (Crs::Wgs84, Some(origin)) => Place::Wgs84(origin),
        (Crs::Local, _) => Place::Local,
    };
    let meta = meta(s, crs, origin)?;
    let features = features(s, place);
    let mut out = String::from("{\n  \"type\": \"FeatureCollection\",\n");
    out.push_str(&format!("  \"drivecheck\": {meta},\n  \"features\": [\n"));
    let lines: Vec<String> = features.iter().map(|f| format!("    {f}")).collect();
    out.push_str(&lines.join(",\n"));
    out.push_str("\n  ]\n}\n");
    Ok(out)
}

/// Where positions are written: as they are, or as longitude/latitude around an origin.
#[derive(Clone, Copy)]
enum Place {
    Local,
    Wgs84(EnuOrigin),
}

impl Place {
    fn position(self, p: Point) -> Value {
        match self {
            Place::Local => json!([p.x, p.y]),
            Place::Wgs84(origin) => {
                let (lat, lon, _) = enu_to_geodetic(&origin, [p.x, p.y, 0.0]);
                json!([lon, lat])
            }
        }
    }

    /// A closed ring (its first position repeated at the end), vertices in the scenario's order.
    fn ring(self, points: &[Point]) -> Value {
        let closed = points.iter().chain(points.first());
        Value::Array(closed.map(|&p| self.position(p)).collect())
    }

    fn line(self, points: impl IntoIterator<Item = Point>) -> Value {
        Value::Array(points.into_iter().map(|p| self.position(p)).collect())
    }
}

/// The collection's `drivecheck` member: version, coordinate kind, origin, name, description and
/// the settings (taken from the canonical TOML, so that they are the very values it hashes).
fn meta(s: &Scenario, crs: Crs, origin: Option<EnuOrigin>) -> Result<Value, GeoJsonWriteError> {
    let mut meta = Map::new();
    meta.insert("version".into(), json!(VERSION));
    meta.insert("crs".into(), json!(crs.name()));
    if let Some(o) = origin {
        meta.insert(
            "origin".into(),
            json!({"lat": o.lat, "lon": o.lon, "height": o.height}),
        );
    }
    meta.insert("name".into(), json!(s.name));
    if let Some(description) = &s.description {
        meta.insert("description".into(), json!(description));
    }
    let canonical: toml::Table =
        toml::from_str(&s.to_toml()).map_err(|e| GeoJsonWriteError::Settings(e.to_string()))?;
    for key in ["vehicle", "generator", "campaign"] {
        let value = canonical.get(key).map(serde_json::to_value).transpose();
        let value = value.map_err(|e| GeoJsonWriteError::Settings(e.to_string()))?;
        meta.insert(key.into(), value.unwrap_or(Value::Null));
    }
    Ok(Value::Object(meta))
}

fn feature(properties: Value, geometry: Value) -> Value {
    json!({"type": "Feature", "properties": properties, "geometry": geometry})
}

fn features(s: &Scenario, place: Place) -> Vec<Value> {
    let polygon =
        |points: &[Point]| json!({"type": "Polygon", "coordinates": [place.ring(points)]});
    let mut out = vec![feature(
        json!({"drivecheck": "fence"}),
        polygon(s.area.fence().vertices()),
    )];
    for cutout in s.area.cutouts() {
        out.push(feature(
            json!({"drivecheck": "cutout"}),
            polygon(cutout.vertices()),
        ));
    }
    for (which, route) in [("start", &s.start_route), ("recovery", &s.recovery_route)] {
        out.push(route_feature(which, route, place));
    }
    for a in &s.anchors {
        out.push(feature(
            json!({"drivecheck": "anchor", "id": a.id, "height": a.height}),
            json!({"type": "Point", "coordinates": place.position(a.position())}),
        ));
    }
    for o in &s.environment.obstacles {
        out.push(feature(
            json!({"drivecheck": "obstacle", "name": o.name, "illustrative": o.illustrative}),
            polygon(o.polygon.vertices()),
        ));
    }
    for w in &s.environment.walls {
        out.push(feature(
            json!({"drivecheck": "wall", "name": w.name, "illustrative": w.illustrative}),
            json!({"type": "LineString", "coordinates": place.line([w.a, w.b])}),
        ));
    }
    out
}

fn route_feature(which: &str, route: &Route, place: Place) -> Value {
    let speeds: Vec<f64> = route.points.iter().map(|p| p.speed).collect();
    feature(
        json!({"drivecheck": "route", "route": which, "speeds": speeds}),
        json!({"type": "LineString", "coordinates": place.line(route.positions())}),
    )
}
