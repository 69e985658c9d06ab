//! The `drivecheck` command line, end to end: exit codes, JSON outputs, files written.

use crate::common;

use common::drivecheck;

use std::process::Output;

use scenarios::bundled;
use trajgen::{Point, check_route};

fn json(output: &Output) -> serde_json::Value {
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not JSON ({e}): {}\nstderr: {}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        )
    })
}

#[test]
fn area_validate_reports_the_documented_keys_and_exits_zero_when_safe() {
    let out = drivecheck(&[
        "area",
        "validate",
        "cutouts-four",
        "--km",
        "2",
        "--seed",
        "3",
        "--json",
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = json(&out);
    for key in [
        "verdict",
        "km",
        "extensions",
        "failures",
        "max_outer_tries",
        "mean_outer_tries",
        "p99_outer_tries",
        "wall_s",
        "coverage",
        "hotspots",
    ] {
        assert!(report.get(key).is_some(), "missing key {key} in {report}");
    }
    assert_eq!(report["verdict"], "safe");
    assert!(report["km"].as_f64().unwrap() >= 2.0);
    assert_eq!(report["failures"], 0);
}

#[test]
fn area_validate_exits_one_when_the_area_is_unsafe() {
    // With only 2 outer tries allowed, the reference strategy needs more than half the limit
    // somewhere in the tight parking lot: the verdict must be unsafe, and the exit status 1.
    let dir = tempfile::tempdir().unwrap();
    let text = bundled::text("parking-lot-2anchors").unwrap();
    assert!(text.contains("outer_tries = 5000"));
    let strict = text.replace("outer_tries = 5000", "outer_tries = 2");
    let path = dir.path().join("strict.toml");
    std::fs::write(&path, strict).unwrap();
    let out = drivecheck(&[
        "area",
        "validate",
        path.to_str().unwrap(),
        "--km",
        "1",
        "--seed",
        "1",
        "--json",
        "--strategy",
        "reference",
    ]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(json(&out)["verdict"], "unsafe");
}

#[test]
fn area_validate_writes_a_picture() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("area.svg");
    let out = drivecheck(&[
        "area",
        "validate",
        "courtyard",
        "--km",
        "0.5",
        "--seed",
        "1",
        "--svg",
        svg.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0));
    let picture = std::fs::read_to_string(&svg).unwrap();
    assert!(picture.starts_with("<svg") && picture.trim_end().ends_with("</svg>"));
    assert!(picture.contains("<polygon"), "the fence is drawn");
    assert!(picture.contains("<polyline"), "the trajectory is drawn");
}

#[test]
fn a_missing_scenario_is_an_error_with_exit_two() {
    let out = drivecheck(&["area", "validate", "no-such-area", "--km", "1"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no-such-area") && stderr.contains("parking-lot-rock"),
        "{stderr}"
    );
}

#[test]
fn route_generate_extends_the_start_route_with_drivable_points() {
    let out = drivecheck(&[
        "route",
        "generate",
        "parking-lot-rock",
        "--points",
        "30",
        "--seed",
        "9",
        "--json",
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let route = json(&out);
    let read = |key: &str| -> Vec<Point> {
        route[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| Point::new(p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
            .collect()
    };
    let (start, points) = (read("start_route"), read("points"));
    assert_eq!(points.len(), 30);
    assert!(route["stats"].is_object());
    let scenario = bundled::load("parking-lot-rock").unwrap().scenario;
    // The generated points continue the start route: check them together with its last segment.
    let joined: Vec<Point> = start[start.len() - 2..]
        .iter()
        .chain(&points)
        .copied()
        .collect();
    let heading = (joined[1] - joined[0]).heading();
    check_route(
        &scenario.area,
        &joined[1..],
        &scenario.constraints(),
        Some(heading),
    )
    .unwrap();
}

#[test]
fn route_generate_is_repeatable_from_its_seed() {
    let args = [
        "route",
        "generate",
        "courtyard",
        "--points",
        "12",
        "--seed",
        "42",
        "--json",
    ];
    assert_eq!(drivecheck(&args).stdout, drivecheck(&args).stdout);
}

#[test]
fn scenario_import_converts_reference_xml_to_a_loadable_toml() {
    let dir = tempfile::tempdir().unwrap();
    let xml = dir.path().join("area.xml");
    std::fs::write(&xml, XML).unwrap();
    let toml = dir.path().join("area.toml");
    let out = drivecheck(&[
        "scenario",
        "import",
        xml.to_str().unwrap(),
        "-o",
        toml.to_str().unwrap(),
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let from_xml = scenarios::load(&xml).unwrap().scenario;
    let from_toml = scenarios::load(&toml).unwrap().scenario;
    assert_eq!(from_xml, from_toml);
    let check = drivecheck(&["scenario", "check", toml.to_str().unwrap()]);
    assert_eq!(check.status.code(), Some(0));
    // An existing -o file is replaced only with --force.
    std::fs::write(&toml, "mine").unwrap();
    let again = [
        "scenario",
        "import",
        xml.to_str().unwrap(),
        "-o",
        toml.to_str().unwrap(),
    ];
    let refused = drivecheck(&again);
    assert_eq!(refused.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--force"));
    assert_eq!(std::fs::read_to_string(&toml).unwrap(), "mine");
    let forced = drivecheck(&[&again[..], &["--force"]].concat());
    assert_eq!(forced.status.code(), Some(0));
    assert_eq!(scenarios::load(&toml).unwrap().scenario, from_xml);
}

/// `drivecheck report --out` replaces a report, never a recorded file.
#[test]
fn a_report_does_not_overwrite_a_case_file() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("run");
    let run = drivecheck(&[
        "run",
        "-q",
        "--tests",
        "1",
        "--seed",
        "1",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let case = out_dir.join("case-000.json");
    let before = std::fs::read(&case).unwrap();
    let refused = drivecheck(&[
        "report",
        out_dir.to_str().unwrap(),
        "--out",
        case.to_str().unwrap(),
    ]);
    assert_eq!(refused.status.code(), Some(2));
    assert_eq!(std::fs::read(&case).unwrap(), before);
}

/// A small area in the reference XML: a 20 m square fence, a start and a recovery route.
const XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<routes>
  <anchors><anchor><x>0</x><y>0</y><height>1</height><id>7</id></anchor></anchors>
  <route><id>0</id>
    <point><x>5</x><y>2</y><speed>1</speed><time>0</time></point>
    <point><x>6.5</x><y>2</y><speed>1</speed><time>0</time></point>
    <point><x>8</x><y>2</y><speed>1</speed><time>0</time></point>
  </route>
  <route><id>1</id>
    <point><x>2</x><y>2</y><speed>1</speed><time>0</time></point>
    <point><x>3.5</x><y>2</y><speed>1</speed><time>0</time></point>
  </route>
  <route><id>2</id>
    <point><x>-1</x><y>-1</y><speed>1</speed><time>0</time></point>
    <point><x>19</x><y>-1</y><speed>1</speed><time>0</time></point>
    <point><x>19</x><y>19</y><speed>1</speed><time>0</time></point>
    <point><x>-1</x><y>19</y><speed>1</speed><time>0</time></point>
  </route>
</routes>
"#;

#[test]
fn route_return_joins_the_recovery_route_with_a_drivable_route() {
    let out = drivecheck(&[
        "route",
        "return",
        "cutouts-four",
        "--from",
        "25,-915,90",
        "--seed",
        "2",
        "--json",
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let route = json(&out);
    for key in ["points", "length_m", "lower_bound_m", "ratio", "plan_ms"] {
        assert!(route.get(key).is_some(), "missing key {key} in {route}");
    }
    assert!(route["ratio"].as_f64().unwrap() >= 1.0);
    let scenario = bundled::load("cutouts-four").unwrap().scenario;
    let recovery = scenario.recovery_route.positions();
    let next = recovery[route["join_segment"].as_u64().unwrap() as usize + 1];
    let mut points: Vec<Point> = route["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| Point::new(p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
        .collect();
    assert_eq!(points[0], Point::new(25.0, -915.0));
    points.push(next);
    let heading = 90f64.to_radians();
    check_route(
        &scenario.area,
        &points,
        &scenario.constraints(),
        Some(heading),
    )
    .unwrap();
}

#[test]
fn route_return_refuses_a_pose_outside_the_area() {
    let out = drivecheck(&["route", "return", "courtyard", "--from", "500,500,0"]);
    assert_eq!(out.status.code(), Some(2));
    let out = drivecheck(&["route", "return", "courtyard", "--from", "1,2"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("X,Y,HEADING_DEG"));
}

#[test]
fn route_return_exits_one_when_the_car_is_boxed_in() {
    // In the courtyard's narrow southern pocket, 1.2 m from its edge ahead: turning either way
    // meets an edge or the pocket's narrowing tip.
    let out = drivecheck(&[
        "route",
        "return",
        "courtyard",
        "--from",
        "0,-11.73,135.8",
        "--seed",
        "1",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("moved by hand"));
}

#[test]
fn a_reader_that_goes_away_ends_the_command_quietly_like_a_unix_tool() {
    use std::process::{Command, Stdio};
    // 5000 points are far more than a pipe holds: writing goes on after the reader has gone.
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args([
            "route",
            "generate",
            "courtyard",
            "--points",
            "5000",
            "--seed",
            "1",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(141), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// `--version` names the commit the binary was built from (or says it is unknown).
#[test]
fn the_version_names_the_revision() {
    let out = drivecheck(&["--version"]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    let revision = text
        .trim()
        .strip_prefix(&format!("drivecheck {} (", env!("CARGO_PKG_VERSION")))
        .and_then(|rest| rest.strip_suffix(')'))
        .unwrap_or_else(|| panic!("{text}"));
    let hash = revision.strip_prefix("revision ");
    assert!(
        revision == "unknown revision"
            || hash.is_some_and(|h| h.len() == 12 && h.chars().all(|c| c.is_ascii_hexdigit())),
        "{text}"
    );
}

/// `scenario export NAME --geojson` then `scenario import` of the file gives the same scenario
/// hash, for every bundled scenario (`scenario list --json` names them and their hashes).
#[test]
fn every_bundled_scenario_exported_as_geojson_imports_to_the_same_hash() {
    let dir = tempfile::tempdir().unwrap();
    let listed = drivecheck(&["scenario", "list", "--json"]);
    assert_eq!(listed.status.code(), Some(0));
    let list = json(&listed);
    let list = list["scenarios"].as_array().unwrap();
    assert_eq!(list.len(), bundled::names().len());
    for (k, entry) in list.iter().enumerate() {
        let name = entry["name"].as_str().unwrap();
        for key in [
            "drivable_area_m2",
            "cutouts",
            "anchors",
            "description",
            "hash",
        ] {
            assert!(entry.get(key).is_some(), "{name}: no {key}");
        }
        let geojson = dir.path().join(format!("{name}.geojson"));
        let toml = dir.path().join(format!("{name}.toml"));
        let (geojson, toml) = (geojson.to_str().unwrap(), toml.to_str().unwrap());
        let out = drivecheck(&["scenario", "export", name, "--crs", "local", "-o", geojson]);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        // The old spelling `--output` still works.
        let output = if k == 0 { "--output" } else { "--out" };
        let out = drivecheck(&["scenario", "import", geojson, output, toml]);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let note = String::from_utf8_lossy(&out.stderr);
        assert!(
            note.contains("note: ") && note.contains("local metres (as the file says)"),
            "{note}"
        );
        let checked = drivecheck(&["scenario", "check", toml, "--json"]);
        assert_eq!(checked.status.code(), Some(0));
        let summary = json(&checked);
        assert_eq!(summary["hash"], entry["hash"], "{name}");
        assert_eq!(summary["valid"], true);
        assert!(summary["warnings"].is_array());
        // Standard output is the GeoJSON without --out.
        let printed = drivecheck(&["scenario", "export", name, "--crs", "local"]);
        assert_eq!(
            String::from_utf8_lossy(&printed.stdout),
            std::fs::read_to_string(geojson).unwrap()
        );
    }
}

/// With an origin the export is longitude/latitude (RFC 7946 positions), and its import says
/// which origin it used; without an origin (the default is wgs84, `--geojson` or not), exit 2
/// with an error that says to give one.
#[test]
fn scenario_export_writes_longitude_latitude_around_an_origin() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("court.geojson");
    let file = file.to_str().unwrap();
    let args = [
        "scenario",
        "export",
        "courtyard",
        "--geojson",
        "--origin",
        "-33.9,151.2,10",
        "-o",
        file,
    ];
    assert_eq!(drivecheck(&args).status.code(), Some(0));
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    assert_eq!(written["drivecheck"]["crs"], "wgs84");
    let lon = written["features"][0]["geometry"]["coordinates"][0][0][0]
        .as_f64()
        .unwrap();
    assert!((lon - 151.2).abs() < 0.01, "{lon}");
    let out = drivecheck(&["scenario", "import", file]);
    assert_eq!(out.status.code(), Some(0));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains("origin -33.9, 151.2, 10 m (the file's drivecheck.origin)"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for refused in [
        &["scenario", "export", "courtyard"][..],
        &[
            "scenario",
            "export",
            "courtyard",
            "--geojson",
            "--crs",
            "wgs84",
        ],
        &["scenario", "import", file, "-o", file],
    ] {
        assert_eq!(drivecheck(refused).status.code(), Some(2), "{refused:?}");
    }
    let said = drivecheck(&["scenario", "export", "courtyard"]);
    assert!(
        String::from_utf8_lossy(&said.stderr).contains("--origin"),
        "{}",
        String::from_utf8_lossy(&said.stderr)
    );
}

/// Every bundled scenario exported for QGIS (WGS84, around an origin) is valid RFC 7946 GeoJSON
/// to an independent validator, `geojson-validator` (PyPI: structure, closed rings, exterior
/// rings counter-clockwise and holes clockwise, latitudes and longitudes in range), run by
/// `DRIVECHECK_PYTHON` (which `.ci/run` provides with the package).
#[test]
fn every_bundled_scenario_exported_for_qgis_is_valid_rfc_7946_to_an_independent_validator() {
    let python = std::env::var("DRIVECHECK_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let script = r#"
import json, sys
import geojson_validator
for path in sys.argv[1:]:
    document = json.load(open(path))
    structure = geojson_validator.validate_structure(document)
    geometries = geojson_validator.validate_geometries(document)
    lat_lon = geometries["problematic"].get("outside_lat_lon_boundaries")
    print(json.dumps({"file": path, "structure": structure, "invalid": geometries["invalid"],
                      "outside_lat_lon": lat_lon}))
"#;
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for name in bundled::names() {
        let file = dir.path().join(format!("{name}.geojson"));
        let file = file.to_str().unwrap().to_owned();
        let out = drivecheck(&[
            "scenario",
            "export",
            name,
            "--origin",
            "57.7,11.9,30",
            "-o",
            &file,
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", common::text(&out));
        files.push(file);
    }
    let run = std::process::Command::new(&python)
        .args(["-c", script])
        .args(&files)
        .output();
    let Ok(run) = run else {
        common::skipped("python-geojson", &format!("{python} does not run"));
        return;
    };
    if !run.status.success() {
        let stderr = String::from_utf8_lossy(&run.stderr);
        if stderr.contains("No module named") {
            common::skipped(
                "python-geojson",
                &format!("the geojson-validator package is not installed ({python})"),
            );
            return;
        }
        panic!("geojson-validator failed: {stderr}");
    }
    let stdout = String::from_utf8_lossy(&run.stdout);
    let results: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(results.len(), files.len(), "{stdout}");
    for result in &results {
        assert_eq!(result["structure"], serde_json::json!({}), "{result}");
        assert_eq!(result["invalid"], serde_json::json!({}), "{result}");
        assert!(result["outside_lat_lon"].is_null(), "{result}");
    }
}
