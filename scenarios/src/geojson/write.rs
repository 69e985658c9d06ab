//! Writing a scenario as a GeoJSON FeatureCollection (the schema of `docs/geojson.md`).

use serde_json::{Map, Value, json};
use trajgen::{Point, Polygon};

use super::{CRS_LOCAL_NAME, Crs, GeoJsonWriteError, VERSION};
use crate::geodesy::enu_to_geodetic;
use crate::model::{EnuOrigin, Route, Scenario};

/// How to write a scenario as GeoJSON.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WriteOptions {
    /// The coordinate kind; `None`: WGS84 longitude/latitude (RFC 7946's), which needs an origin
    /// (given or the scenario's): without one, [`GeoJsonWriteError::NoOrigin`]. Local metres are
    /// written only when asked for (`Some(Crs::Local)`), and then say so (see [`to_geojson`]).
    pub crs: Option<Crs>,
    /// The local frame's origin on the globe, in place of the scenario's (written as the
    /// collection's origin, so that the file reads back with it).
    pub origin: Option<EnuOrigin>,
}

/// The scenario as a GeoJSON FeatureCollection: one feature a line, the fence first, then the
/// cutouts, the start and recovery routes, the anchors, obstacles and walls. In local metres it
/// reads back ([`super::from_geojson_str`]) to the same scenario and hash; in longitude/latitude
/// to within a micrometre.
///
/// Every polygon ring follows RFC 7946's right-hand rule (an exterior ring counter-clockwise);
/// one drawn clockwise is written from its first vertex backwards, with the property
/// `"drawn": "clockwise"`, from which the reader restores the order drawn.
///
/// By default the coordinates are WGS84 longitude/latitude, which need an origin; local metres
/// (`crs: Some(Crs::Local)`) are not RFC 7946 coordinates, so that file also carries the 2008
/// `crs` member naming the local frame ([`CRS_LOCAL_NAME`]): a reader that honours it does not
/// take the metres for degrees.
pub fn to_geojson(s: &Scenario, options: &WriteOptions) -> Result<String, GeoJsonWriteError> {
    let origin = options.origin.or(s.origin);
    let crs = options.crs.unwrap_or(Crs::Wgs84);
    let place = match (crs, origin) {
        (Crs::Wgs84, None) => return Err(GeoJsonWriteError::NoOrigin),
        (Crs::Wgs84, Some(origin)) => Place::Wgs84(origin),
        (Crs::Local, _) => Place::Local,
    };
    let meta = meta(s, crs, origin)?;
    let features = features(s, place);
    let mut out = String::from("{\n  \"type\": \"FeatureCollection\",\n");
    if crs == Crs::Local {
        let member = json!({"type": "name", "properties": {"name": CRS_LOCAL_NAME}});
        out.push_str(&format!("  \"crs\": {member},\n"));
    }
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

    /// A closed ring (its first position repeated at the end) by the right-hand rule: vertices in
    /// the scenario's order when they run counter-clockwise, else from the first backwards.
    fn ring(self, points: &[Point], clockwise: bool) -> Value {
        let first = points.first();
        let closed: Vec<&Point> = if clockwise {
            first
                .into_iter()
                .chain(points.iter().skip(1).rev())
                .chain(first)
                .collect()
        } else {
            points.iter().chain(first).collect()
        };
        Value::Array(closed.into_iter().map(|&p| self.position(p)).collect())
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
    // A polygon feature with `properties`, its ring by the right-hand rule.
    let polygon = |mut properties: Value, polygon: &Polygon| {
        let clockwise = polygon.signed_area() < 0.0;
        if clockwise {
            properties["drawn"] = json!("clockwise");
        }
        let ring = place.ring(polygon.vertices(), clockwise);
        feature(
            properties,
            json!({"type": "Polygon", "coordinates": [ring]}),
        )
    };
    let mut out = vec![polygon(json!({"drivecheck": "fence"}), s.area.fence())];
    for cutout in s.area.cutouts() {
        out.push(polygon(json!({"drivecheck": "cutout"}), cutout));
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
        out.push(polygon(
            json!({"drivecheck": "obstacle", "name": o.name, "illustrative": o.illustrative}),
            &o.polygon,
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
