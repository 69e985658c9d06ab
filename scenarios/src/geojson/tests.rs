//! The GeoJSON reader and writer: round trips, what QGIS writes, and hostile input.

use proptest::prelude::*;
use serde_json::{Value, json};

use super::*;
use crate::model::Scenario;
use crate::{Point, bundled};

fn read(text: &str) -> Result<Imported, ScenarioError> {
    from_geojson_str(text, "t.geojson", "t", &ReadOptions::default())
}

fn error(text: &str) -> String {
    read(text).unwrap_err().to_string()
}

/// Every point of a scenario's geometry, in a fixed order.
fn points(s: &Scenario) -> Vec<Point> {
    let mut all: Vec<Point> = s.area.fence().vertices().to_vec();
    s.area
        .cutouts()
        .iter()
        .for_each(|c| all.extend(c.vertices()));
    all.extend(s.start_route.positions());
    all.extend(s.recovery_route.positions());
    all.extend(s.anchors.iter().map(|a| a.position()));
    for o in &s.environment.obstacles {
        all.extend(o.polygon.vertices());
    }
    for w in &s.environment.walls {
        all.extend([w.a, w.b]);
    }
    all
}

#[test]
fn every_bundled_scenario_reads_back_from_local_metres_with_its_hash() {
    let local = WriteOptions {
        crs: Some(Crs::Local),
        origin: None,
    };
    for name in bundled::names() {
        let scenario = bundled::load(name).unwrap().scenario;
        let text = to_geojson(&scenario, &local).unwrap();
        let imported = read(&text).unwrap();
        assert_eq!(imported.crs, (Crs::Local, CrsSource::File), "{name}");
        assert_eq!(imported.loaded.scenario, scenario, "{name}");
        assert_eq!(imported.loaded.scenario.hash(), scenario.hash(), "{name}");
    }
}

#[test]
fn every_bundled_scenario_reads_back_from_longitude_latitude_within_a_millimetre() {
    let origin = EnuOrigin {
        lat: 61.45,
        lon: 23.85,
        height: 120.0,
    };
    for name in bundled::names() {
        let scenario = bundled::load(name).unwrap().scenario;
        let options = WriteOptions {
            crs: None,
            origin: Some(origin),
        };
        let text = to_geojson(&scenario, &options).unwrap();
        assert!(text.contains("\"crs\":\"wgs84\""), "{text}");
        let imported = read(&text).unwrap();
        assert_eq!(imported.origin, Some((origin, OriginSource::File)));
        let again = imported.loaded.scenario;
        assert_eq!(again.origin, Some(origin));
        assert_eq!(again.campaign, scenario.campaign);
        let (a, b) = (points(&scenario), points(&again));
        assert_eq!(a.len(), b.len());
        let worst = a
            .iter()
            .zip(&b)
            .map(|(p, q)| p.dist(*q))
            .fold(0.0, f64::max);
        assert!(worst < 1e-3, "{name}: {worst} m");
    }
}

#[test]
fn a_scenario_with_an_origin_is_written_in_longitude_latitude_unless_local_is_asked() {
    let mut scenario = bundled::load("courtyard").unwrap().scenario;
    assert!(matches!(
        to_geojson(
            &scenario,
            &WriteOptions {
                crs: Some(Crs::Wgs84),
                origin: None
            }
        ),
        Err(GeoJsonWriteError::NoOrigin)
    ));
    scenario.origin = Some(EnuOrigin {
        lat: -33.9,
        lon: 151.2,
        height: 0.0,
    });
    let wgs84 = to_geojson(&scenario, &WriteOptions::default()).unwrap();
    assert!(
        wgs84.contains("\"crs\":\"wgs84\"") && wgs84.contains("[151.2"),
        "{wgs84}"
    );
    let local = WriteOptions {
        crs: Some(Crs::Local),
        origin: None,
    };
    let text = to_geojson(&scenario, &local).unwrap();
    assert_eq!(read(&text).unwrap().loaded.scenario.hash(), scenario.hash());
}

/// Twice the signed area of a closed ring by the shoelace formula (positive: counter-clockwise).
fn ring_orientation(ring: &[Value]) -> f64 {
    let xy = |v: &Value| (v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    ring.windows(2)
        .map(|w| {
            let ((x0, y0), (x1, y1)) = (xy(&w[0]), xy(&w[1]));
            x0 * y1 - x1 * y0
        })
        .sum()
}

#[test]
fn without_an_origin_the_default_export_is_refused_and_local_metres_say_so() {
    let scenario = bundled::load("courtyard").unwrap().scenario;
    assert!(scenario.origin.is_none());
    let error = to_geojson(&scenario, &WriteOptions::default()).unwrap_err();
    assert_eq!(error, GeoJsonWriteError::NoOrigin);
    assert!(error.to_string().contains("--origin LAT,LON"), "{error}");
    let local = WriteOptions {
        crs: Some(Crs::Local),
        origin: None,
    };
    let text = to_geojson(&scenario, &local).unwrap();
    let document: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(
        document["crs"],
        json!({"type": "name", "properties": {"name": CRS_LOCAL_NAME}})
    );
    assert_eq!(document["drivecheck"]["crs"], json!(CRS_LOCAL));
    // The legacy member alone (a tool that kept it but not drivecheck's own) reads as local.
    let mut legacy_only = document.clone();
    legacy_only["drivecheck"]
        .as_object_mut()
        .unwrap()
        .remove("crs");
    let imported = read(&legacy_only.to_string()).unwrap();
    assert_eq!(imported.crs, (Crs::Local, CrsSource::File));
    assert_eq!(imported.loaded.scenario.hash(), scenario.hash());
}

#[test]
fn every_ring_follows_the_right_hand_rule_and_every_position_is_longitude_latitude() {
    let origin = EnuOrigin {
        lat: 61.45,
        lon: 23.85,
        height: 120.0,
    };
    let options = WriteOptions {
        crs: None,
        origin: Some(origin),
    };
    let mut clockwise_seen = 0;
    for name in bundled::names() {
        let scenario = bundled::load(name).unwrap().scenario;
        let text = to_geojson(&scenario, &options).unwrap();
        let document: Value = serde_json::from_str(&text).unwrap();
        assert!(
            document.get("crs").is_none(),
            "{name}: RFC 7946 has no crs member"
        );
        for (i, feature) in document["features"].as_array().unwrap().iter().enumerate() {
            let geometry = &feature["geometry"];
            let positions: Vec<&Value> = match geometry["type"].as_str().unwrap() {
                "Polygon" => {
                    let rings = geometry["coordinates"].as_array().unwrap();
                    for (k, ring) in rings.iter().enumerate() {
                        let ring = ring.as_array().unwrap();
                        assert!(ring.len() >= 4 && ring[0] == ring[ring.len() - 1]);
                        let area = ring_orientation(ring);
                        // Exterior counter-clockwise, holes clockwise.
                        assert!(
                            if k == 0 { area > 0.0 } else { area < 0.0 },
                            "{name}: features[{i}] ring {k}: {area}"
                        );
                    }
                    if feature["properties"]["drawn"] == json!("clockwise") {
                        clockwise_seen += 1;
                    }
                    rings.iter().flat_map(|r| r.as_array().unwrap()).collect()
                }
                "LineString" => geometry["coordinates"].as_array().unwrap().iter().collect(),
                "Point" => vec![&geometry["coordinates"]],
                other => panic!("{other}"),
            };
            for p in positions {
                let (lon, lat) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
                assert!((-180.0..=180.0).contains(&lon), "{name}: {lon}");
                assert!((-90.0..=90.0).contains(&lat), "{name}: {lat}");
                // Around the origin: the areas are tens of metres wide.
                assert!((lat - 61.45).abs() < 0.01 && (lon - 23.85).abs() < 0.02);
            }
        }
        // And it reads back: the clockwise rings in the order drawn.
        let again = read(&text).unwrap().loaded.scenario;
        assert_eq!(
            again.area.fence().signed_area().signum(),
            scenario.area.fence().signed_area().signum(),
            "{name}"
        );
        assert_eq!(
            again.area.fence().vertices().len(),
            scenario.area.fence().vertices().len()
        );
    }
    // courtyard's fence is drawn clockwise.
    assert!(clockwise_seen > 0);
}

/// A QGIS-like collection in longitude/latitude around (61.45° N, 23.85° E): a 40 × 30 m
/// fence with a hole, anchors, and the two routes; `extra` features are appended.
fn qgis(extra: &[Value]) -> Value {
    let lonlat = |e: f64, n: f64| {
        let origin = EnuOrigin {
            lat: 61.45,
            lon: 23.85,
            height: 0.0,
        };
        let (lat, lon, _) = crate::geodesy::enu_to_geodetic(&origin, [e, n, 0.0]);
        json!([lon, lat])
    };
    let ring = |points: &[(f64, f64)]| {
        let mut ring: Vec<Value> = points.iter().map(|&(e, n)| lonlat(e, n)).collect();
        ring.push(ring[0].clone());
        Value::Array(ring)
    };
    let line = |points: &[(f64, f64)]| {
        points
            .iter()
            .map(|&(e, n)| lonlat(e, n))
            .collect::<Vec<_>>()
    };
    let mut features = vec![
        json!({"type": "Feature", "properties": {"name": "fence"}, "geometry": {"type": "Polygon",
            "coordinates": [ring(&[(0., 0.), (40., 0.), (40., 30.), (0., 30.)]),
                            ring(&[(25., 10.), (25., 15.), (30., 15.), (30., 10.)])]}}),
        json!({"type": "Feature", "properties": {"id": 7}, "geometry": {"type": "Point",
            "coordinates": lonlat(-1., -1.)}}),
        json!({"type": "Feature", "properties": {"drivecheck": "route", "route": "start",
            "speed": 1.0}, "geometry": {"type": "LineString",
            "coordinates": line(&[(5., 5.), (6.5, 5.), (8., 5.)])}}),
        json!({"type": "Feature", "properties": {"drivecheck": "route", "route": "recovery",
            "speeds": [1.0, 1.0, 0.5]}, "geometry": {"type": "LineString",
            "coordinates": line(&[(5., 10.), (5., 8.5), (5., 7.)])}}),
    ];
    features.extend(extra.iter().cloned());
    json!({"type": "FeatureCollection", "features": features})
}

#[test]
fn a_qgis_collection_is_read_by_geometry_with_the_first_vertex_as_origin() {
    let extra = json!({"type": "Feature", "properties": null, "geometry": {"type": "Point",
        "coordinates": [23.8508, 61.4503, 44.0]}});
    let imported = read(&qgis(&[extra]).to_string()).unwrap();
    assert_eq!(imported.crs, (Crs::Wgs84, CrsSource::Inferred));
    let (origin, from) = imported.origin.unwrap();
    assert_eq!(from, OriginSource::FirstVertex);
    assert!((origin.lat - 61.45).abs() < 1e-12 && (origin.lon - 23.85).abs() < 1e-12);
    assert_eq!(origin.height, 0.0);
    let s = &imported.loaded.scenario;
    assert_eq!(s.origin, Some(origin));
    assert_eq!(s.area.cutouts().len(), 1);
    let corner = s.area.fence().vertices()[2];
    assert!(corner.dist(Point::new(40.0, 30.0)) < 1e-6, "{corner:?}");
    let ids: Vec<u8> = s.anchors.iter().map(|a| a.id).collect();
    assert_eq!(ids, [7, 1]);
    assert_eq!(s.recovery_route.points[2].speed, 0.5);
    let warnings: Vec<String> = imported
        .loaded
        .warnings
        .iter()
        .map(ToString::to_string)
        .collect();
    for expected in [
        "t.geojson: features[0]: no `drivecheck` property: taken as the fence (the largest polygon; its holes are cutouts)",
        "t.geojson: features[1]: no `drivecheck` property: taken as an anchor (a point)",
        "t.geojson: features[4]: no `id` property: the anchor is numbered 1",
        "t.geojson: features[4]: no `height` property: 0 m assumed (the firmware stores it but does not use it)",
    ] {
        assert!(
            warnings.iter().any(|w| w == expected),
            "{expected}\nnot in {warnings:#?}"
        );
    }
    assert!(warnings.iter().any(|w| w.starts_with(
        "t.geojson: drivecheck.origin: longitude/latitude and no origin given: the fence's first \
         vertex (61.4"
    )));
    assert!(
        imported.note().contains("the fence's first vertex"),
        "{}",
        imported.note()
    );
}

#[test]
fn rings_of_either_winding_closed_or_not_and_a_multipolygon_of_one_are_read() {
    let base = qgis(&[]);
    let fence = || base["features"][0]["geometry"]["coordinates"].clone();
    let mut reversed = base.clone();
    let mut rings = fence();
    for ring in rings.as_array_mut().unwrap() {
        ring.as_array_mut().unwrap().reverse();
    }
    reversed["features"][0]["geometry"]["coordinates"] = rings;
    let mut open = base.clone();
    let mut rings = fence();
    rings[0].as_array_mut().unwrap().pop();
    open["features"][0]["geometry"]["coordinates"] = rings;
    let mut multi = base.clone();
    multi["features"][0]["geometry"] = json!({"type": "MultiPolygon", "coordinates": [fence()]});
    let area = read(&base.to_string())
        .unwrap()
        .loaded
        .scenario
        .area
        .drivable_area();
    for doc in [reversed, open, multi] {
        let s = read(&doc.to_string()).unwrap().loaded.scenario;
        assert_eq!(s.area.fence().vertices().len(), 4);
        assert!((s.area.drivable_area() - area).abs() < 1e-6);
    }
}

#[test]
fn polygons_beside_the_fence_are_cutouts_and_a_marked_fence_wins_over_size() {
    let cutout = |e: f64| {
        let origin = EnuOrigin {
            lat: 61.45,
            lon: 23.85,
            height: 0.0,
        };
        let p = |x: f64, y: f64| {
            let (lat, lon, _) = crate::geodesy::enu_to_geodetic(&origin, [x, y, 0.0]);
            json!([lon, lat])
        };
        json!({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
            "coordinates": [[p(e, 20.), p(e + 2., 20.), p(e + 2., 22.), p(e, 20.)]]}})
    };
    let s = read(&qgis(&[cutout(10.0), cutout(15.0)]).to_string())
        .unwrap()
        .loaded
        .scenario;
    assert_eq!(s.area.cutouts().len(), 3);
    // A small polygon marked as the fence: the big one becomes a cutout, outside it.
    let mut doc = qgis(&[]);
    let mut small = cutout(10.0);
    small["properties"] = json!({"drivecheck": "fence"});
    doc["features"].as_array_mut().unwrap().push(small);
    assert_eq!(
        error(&doc.to_string()),
        "t.geojson: features[0].geometry.coordinates[1]: a Polygon with holes cannot be a cutout"
    );
    // Without its hole, the big polygon is a cutout that is not inside the small fence.
    doc["features"][0]["geometry"]["coordinates"]
        .as_array_mut()
        .unwrap()
        .pop();
    assert_eq!(
        error(&doc.to_string()),
        "t.geojson: features[0].geometry.coordinates[0] (cutouts[0]): not entirely inside the fence"
    );
}

#[test]
fn bad_features_are_named_by_index_and_member() {
    let with = |i: usize, member: &str, value: Value| {
        let mut doc = qgis(&[]);
        doc["features"][i][member] = value;
        error(&doc.to_string())
    };
    let line = json!({"type": "LineString", "coordinates": [[23.85, 61.45], [23.86, 61.45]]});
    let mut doc = qgis(&[]);
    doc["features"][0]["properties"] = json!({"drivecheck": "fence"});
    doc["features"][0]["geometry"] = line.clone();
    assert_eq!(
        error(&doc.to_string()),
        "t.geojson: features[0].geometry: a LineString cannot be a fence"
    );
    assert_eq!(
        with(2, "properties", json!({"drivecheck": "road"})),
        "t.geojson: features[2].properties.drivecheck: `road` is not a role: expected fence, \
         cutout, anchor, route, obstacle or wall"
    );
    assert_eq!(
        with(
            2,
            "properties",
            json!({"drivecheck": "route", "route": "start"})
        ),
        "t.geojson: features[2].properties: a route needs `speed` (m/s, every point) or `speeds` \
         (one per point)"
    );
    assert_eq!(
        with(
            3,
            "properties",
            json!({"drivecheck": "route", "route": "recovery", "speeds": [1]})
        ),
        "t.geojson: features[3].properties.speeds: 1 speed(s) for 3 point(s)"
    );
    assert_eq!(
        with(1, "properties", json!({"id": "seven"})),
        "t.geojson: features[1].properties.id: `seven` is not a whole number"
    );
    assert_eq!(
        with(1, "properties", json!({"id": 300})),
        "t.geojson: features[1] (anchors[0].id): 300 is outside 0–255 (the firmware addresses \
         the UWB module by one byte)"
    );
    assert_eq!(
        with(1, "geometry", json!({"type": "Point", "coordinates": [1]})),
        "t.geojson: features[1].geometry.coordinates: a position is [x, y] or [longitude, \
         latitude] (an optional third number is ignored)"
    );
    assert_eq!(
        with(
            2,
            "geometry",
            json!({"type": "Point", "coordinates": [23.85, 61.45]})
        ),
        "t.geojson: features[2].geometry: a Point cannot be a route"
    );
    assert_eq!(
        with(1, "type", json!("Thing")),
        "t.geojson: features[1].type: expected \"Feature\", found the string \"Thing\""
    );
    let mut doc = qgis(&[]);
    doc["features"].as_array_mut().unwrap().remove(2);
    assert!(error(&doc.to_string()).starts_with("t.geojson: features: no start route: draw it"));
    let mut doc = qgis(&[]);
    doc["features"][2]["properties"] = json!({});
    assert!(
        error(&doc.to_string()).starts_with(
            "t.geojson: features[2].properties: no `drivecheck` property: only polygons"
        )
    );
    // A route point outside the area names its feature and the scenario field.
    let mut doc = qgis(&[]);
    doc["features"][2]["geometry"]["coordinates"][1] = json!([23.8499, 61.4501]);
    assert_eq!(
        error(&doc.to_string()),
        "t.geojson: features[2].geometry.coordinates (start_route[1]): point (-5.334, 11.144) is \
         outside the area"
    );
}

#[test]
fn the_collection_and_its_coordinate_kind_are_checked() {
    assert_eq!(
        error("[1, 2]"),
        "t.geojson: (top level): expected a FeatureCollection object, found an array"
    );
    assert_eq!(
        error(r#"{"type": "Feature"}"#),
        "t.geojson: type: expected \"FeatureCollection\", found the string \"Feature\""
    );
    assert!(
        error("{\n\"type\": ").starts_with("t.geojson:2:"),
        "{}",
        error("{\n\"type\": ")
    );
    let mut doc = qgis(&[]);
    doc["crs"] = json!({"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32635"}});
    assert!(
        error(&doc.to_string()).starts_with(
            "t.geojson: crs.properties.name: coordinates in urn:ogc:def:crs:EPSG::32635: drivecheck reads"
        ),
        "{}",
        error(&doc.to_string())
    );
    doc["crs"] = json!({"type": "name", "properties": {"name": "urn:ogc:def:crs:OGC:1.3:CRS84"}});
    assert_eq!(
        read(&doc.to_string()).unwrap().crs,
        (Crs::Wgs84, CrsSource::File)
    );
    doc["drivecheck"] = json!({"version": 2});
    assert_eq!(
        error(&doc.to_string()),
        "t.geojson: drivecheck.version: format version 2: this drivecheck reads version 1"
    );
    doc["drivecheck"] = json!({"version": 1, "crs": "local-enu-m", "colour": 1});
    assert!(error(&doc.to_string()).starts_with("t.geojson: drivecheck.colour: unknown field"));
    doc["drivecheck"] = json!({"version": 1, "crs": "local-enu-m"});
    let asked = ReadOptions {
        crs: Some(Crs::Wgs84),
        origin: None,
    };
    assert_eq!(
        from_geojson_str(&doc.to_string(), "t.geojson", "t", &asked)
            .unwrap_err()
            .to_string(),
        "t.geojson: drivecheck.crs: the file says its coordinates are local metres, the command \
         line says WGS84 longitude/latitude"
    );
}

#[test]
fn coordinates_that_fit_both_readings_are_refused_until_the_kind_is_given() {
    // A 2 m fence in metres, or a 200 km one in degrees: neither absurd.
    let square = |k: f64| {
        json!({"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
             "coordinates": [[[0., 0.], [k, 0.], [k, k], [0., k], [0., 0.]]]}}]})
    };
    let e = error(&square(1.6).to_string());
    assert!(
        e.starts_with(
            "t.geojson: drivecheck.crs: the coordinates could be longitude and latitude (a fence \
             25"
        ) && e.contains(
            "m across) or local metres (a fence 2.3 m across): say which with --crs \
             wgs84 or --crs local"
        ),
        "{e}"
    );
    // A fence of 7 cm is no test area: longitude/latitude (then the routes are missing).
    let imported = error(&square(0.05).to_string());
    assert!(imported.contains("no start route"), "{imported}");
    // Told: local metres, the fence is read (and the missing routes are the next problem).
    let local = ReadOptions {
        crs: Some(Crs::Local),
        origin: None,
    };
    let e = from_geojson_str(&square(1.6).to_string(), "t.geojson", "t", &local).unwrap_err();
    assert!(e.to_string().contains("no start route"), "{e}");
    // Larger than any area on the globe, or beyond longitude/latitude: metres without asking.
    for k in [20.0, 200.0] {
        let e = error(&square(k).to_string());
        assert!(e.contains("no start route"), "{e}");
    }
}

#[test]
fn an_origin_given_wins_over_the_files_and_moves_the_frame() {
    let doc = qgis(&[]).to_string();
    let origin = EnuOrigin {
        lat: 61.45,
        lon: 23.8499,
        height: 5.0,
    };
    let asked = ReadOptions {
        crs: None,
        origin: Some(origin),
    };
    let imported = from_geojson_str(&doc, "t.geojson", "t", &asked).unwrap();
    assert_eq!(imported.origin, Some((origin, OriginSource::Asked)));
    // 0.0001° of longitude at 61.45° N is about 5.3 m.
    let first = imported.loaded.scenario.area.fence().vertices()[0];
    assert!(
        (first.x - 5.33).abs() < 0.01 && first.y.abs() < 0.01,
        "{first:?}"
    );
}

/// Any JSON value, up to a few levels deep, with the keys a GeoJSON scenario uses.
fn any_json() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<f64>().prop_map(|x| json!(x)),
        any::<i64>().prop_map(|x| json!(x)),
        prop::sample::select(vec![
            "FeatureCollection",
            "Feature",
            "Polygon",
            "MultiPolygon",
            "Point",
            "LineString",
            "fence",
            "cutout",
            "anchor",
            "route",
            "start",
            "recovery",
            "wall",
            "obstacle",
            "wgs84",
            "local-enu-m",
            "",
        ])
        .prop_map(|s| json!(s)),
    ];
    leaf.prop_recursive(5, 64, 6, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
            prop::collection::vec(
                (
                    prop::sample::select(vec![
                        "type",
                        "features",
                        "geometry",
                        "coordinates",
                        "properties",
                        "drivecheck",
                        "route",
                        "speed",
                        "speeds",
                        "id",
                        "height",
                        "name",
                        "version",
                        "crs",
                        "origin",
                    ]),
                    inner
                ),
                0..6
            )
            .prop_map(|pairs| Value::Object(
                pairs.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()
            )),
        ]
    })
}

proptest! {
    #[test]
    fn any_json_is_read_or_refused_without_a_panic(doc in any_json()) {
        let _ = read(&doc.to_string());
    }

    #[test]
    fn a_valid_collection_with_one_value_replaced_is_read_or_refused_without_a_panic(
        feature in 0usize..4,
        path in prop::sample::select(vec!["type", "properties", "geometry", "geometry.type",
            "geometry.coordinates", "properties.drivecheck", "properties.speed",
            "properties.route", "properties.id"]),
        value in any_json(),
    ) {
        let mut doc = qgis(&[]);
        let mut slot = &mut doc["features"][feature];
        for key in path.split('.') {
            slot = &mut slot[key];
        }
        *slot = value;
        match read(&doc.to_string()) {
            Ok(imported) => prop_assert!(imported.loaded.scenario.validate("t").is_ok()),
            Err(e) => prop_assert!(e.to_string().starts_with("t.geojson:"), "{e}"),
        }
    }

    #[test]
    fn any_text_is_read_or_refused_without_a_panic(text in "\\PC{0,200}") {
        let _ = read(&text);
    }
}
