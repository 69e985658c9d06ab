//! GeoJSON as QGIS writes it: `tests/fixtures/geojson/qgis-lot.geojson` is a 40 × 36 m fence with
//! a hole, two anchors and the two routes around (61.45° N, 23.85° E), written by hand the way
//! QGIS 3 exports a layer (longitude/latitude to 8 decimals, a legacy `crs` member, `fid`s, the
//! fence and anchors without `drivecheck` properties).
//!
//! The expected local positions were computed independently of drivecheck, with PROJ 9 (pyproj
//! 3.7): the pipeline `+proj=cart +ellps=WGS84` then `+proj=topocentric +ellps=WGS84 +lat_0=61.45
//! +lon_0=23.85 +h_0=0`, of the file's rounded longitude/latitude at height 0, the origin being the
//! fence's first vertex as drivecheck takes it.

use std::path::PathBuf;

use scenarios::geojson::{Crs, CrsSource, OriginSource};
use scenarios::{Point, load_with};

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures/geojson/qgis-lot.geojson")
}

/// PROJ's east and north, metres (rounded to 0.1 mm).
const FENCE: [(f64, f64); 5] = [
    (0.0, 0.0),
    (39.9999, 0.0002),
    (40.0001, 30.0001),
    (19.9998, 35.9996),
    (0.0, 29.9998),
];
const HOLE: [(f64, f64); 4] = [
    (25.0, 10.0004),
    (25.0, 14.9995),
    (30.0001, 14.9995),
    (30.0001, 10.0004),
];
const ANCHORS: [(f64, f64); 2] = [(-2.0003, -2.0003), (41.9998, 32.0004)];
const START: [(f64, f64); 3] = [(5.0001, 5.0002), (6.5, 5.0002), (8.0, 5.0002)];

fn within_a_centimetre(what: &str, got: &[Point], expected: &[(f64, f64)]) {
    assert_eq!(got.len(), expected.len(), "{what}");
    for (k, (p, &(x, y))) in got.iter().zip(expected).enumerate() {
        let off = p.dist(Point::new(x, y));
        assert!(
            off < 0.01,
            "{what}[{k}]: {p:?} is {off} m from PROJ's ({x}, {y})"
        );
    }
}

#[test]
fn a_qgis_export_in_longitude_latitude_loads_where_proj_puts_it() {
    let imported = load_with(fixture(), &Default::default()).unwrap();
    assert_eq!(imported.crs, (Crs::Wgs84, CrsSource::File));
    let (origin, from) = imported.origin.unwrap();
    assert_eq!(from, OriginSource::FirstVertex);
    assert_eq!((origin.lat, origin.lon, origin.height), (61.45, 23.85, 0.0));
    let s = &imported.loaded.scenario;
    assert_eq!(s.name, "qgis-lot");
    within_a_centimetre("fence", s.area.fence().vertices(), &FENCE);
    assert_eq!(s.area.cutouts().len(), 1);
    within_a_centimetre("hole", s.area.cutouts()[0].vertices(), &HOLE);
    let anchors: Vec<Point> = s.anchors.iter().map(|a| a.position()).collect();
    within_a_centimetre("anchors", &anchors, &ANCHORS);
    let ids: Vec<(u8, f64)> = s.anchors.iter().map(|a| (a.id, a.height)).collect();
    assert_eq!(ids, [(50, 1.5), (234, 0.0)]);
    within_a_centimetre("start_route", &s.start_route.positions(), &START);
    assert!(s.start_route.points.iter().all(|p| p.speed == 1.0));
    // QGIS wrote no roles for the fence and the anchors, and no height for anchor 234: the
    // warnings say how the file was read.
    let warnings: Vec<String> = imported
        .loaded
        .warnings
        .iter()
        .map(|w| format!("{}: {}", w.field, w.kind))
        .collect();
    for expected in [
        "features[0]: no `drivecheck` property: taken as the fence",
        "features[1]: no `drivecheck` property: taken as an anchor",
        "features[2]: no `height` property: 0 m assumed",
        "drivecheck.origin: longitude/latitude and no origin given",
    ] {
        assert!(
            warnings.iter().any(|w| w.starts_with(expected)),
            "{expected}: {warnings:#?}"
        );
    }
}

#[test]
fn the_qgis_export_exported_again_with_its_origin_reads_back_within_a_millimetre() {
    let first = load_with(fixture(), &Default::default())
        .unwrap()
        .loaded
        .scenario;
    let text = scenarios::geojson::to_geojson(&first, &Default::default()).unwrap();
    assert!(
        text.contains("\"crs\":\"wgs84\""),
        "has an origin: longitude/latitude"
    );
    let again = scenarios::geojson::from_geojson_str(&text, "again", "again", &Default::default())
        .unwrap()
        .loaded
        .scenario;
    let pairs = [
        (first.area.fence().vertices(), again.area.fence().vertices()),
        (
            first.area.cutouts()[0].vertices(),
            again.area.cutouts()[0].vertices(),
        ),
    ];
    for (a, b) in pairs {
        for (p, q) in a.iter().zip(b) {
            assert!(p.dist(*q) < 1e-3, "{p:?} {q:?}");
        }
    }
    assert_eq!(first.origin, again.origin);
    assert_eq!(first.anchors.len(), again.anchors.len());
}
