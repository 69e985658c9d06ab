//! Scenario files: malformed files are refused with the right message, the bundled areas load
//! with exactly the expected warnings, the reference XML imports to the bundled scenarios, and the
//! illustrative rock of the rock parking lot really hides anchor 234 from part of the lot, and only part.

use std::path::{Path, PathBuf};

use scenarios::geometry::segments_intersect;
use scenarios::{Point, Polygon, Scenario, bundled};

fn fixtures(dir: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(dir)
}

/// Each malformed file and the message after its path (`path` + this = the whole error text).
const MALFORMED: &[(&str, &str)] = &[
    (
        "syntax-error.toml",
        ":8:5: invalid TOML: missing key for inline table element, expected key",
    ),
    (
        "unknown-field.toml",
        ":22:1: generator.segment_min: unknown field `segment_min`, expected one of \
         `segment_min_m`, `segment_max_m`, `max_turn_deg`, `ahead_margin`, \
         `recovery_ahead_margin`, `inner_tries`, `outer_tries`, `clearance_m`",
    ),
    ("missing-fence.toml", ":1:1: missing field `fence`"),
    (
        "wrong-type.toml",
        ":22:9: campaign.tests: invalid type: string \"ten\", expected usize",
    ),
    (
        "negative-tries.toml",
        ":22:15: generator.inner_tries: invalid value: integer `-5`, expected usize",
    ),
    (
        "fence-two-vertices.toml",
        ":4:9: fence: a polygon needs at least 3 vertices, found 2",
    ),
    (
        "fence-self-intersecting.toml",
        ":4:9: fence: edge 0 (from vertex 0) crosses edge 2 (from vertex 2)",
    ),
    (
        "fence-not-finite.toml",
        ":10:11: fence[5].x: not a finite number",
    ),
    (
        "cutout-outside-fence.toml",
        ":22:5: cutouts[1]: not entirely inside the fence",
    ),
    (
        "cutouts-overlap.toml",
        ":22:5: cutouts[1]: overlaps cutouts[0]",
    ),
    (
        "cutout-self-intersecting.toml",
        ":21:5: cutouts[0]: edge 0 (from vertex 0) crosses edge 2 (from vertex 2)",
    ),
    (
        "start-route-outside.toml",
        ":13:5: start_route[2]: point (11.000, 2.000) is outside the area",
    ),
    (
        "recovery-route-leaves-area.toml",
        ":17:5: recovery_route[1]: segment 1 leaves the area (it meets the fence or a cutout)",
    ),
    (
        "route-one-point.toml",
        ":10:15: start_route: a route needs at least 2 points, found 1",
    ),
    (
        "route-zero-speed.toml",
        ":12:33: start_route[1].speed: must be greater than 0, found 0",
    ),
    (
        "anchor-duplicate-id.toml",
        ":34:6: anchors[2].id: duplicate id 50 (also anchors[0])",
    ),
    (
        "anchor-id-out-of-range.toml",
        ":28:6: anchors[1].id: 300 is outside 0–255 (the firmware addresses the UWB module by one byte)",
    ),
    (
        "too-many-anchors.toml",
        ":21:1: anchors: 21 anchors; the firmware keeps at most 20",
    ),
    (
        "segment-min-above-max.toml",
        ":22:17: generator.segment_min_m: min 2.5 is greater than max 2",
    ),
    (
        "zero-outer-tries.toml",
        ":22:15: generator.outer_tries: must be greater than 0, found 0",
    ),
    (
        "speed-range-reversed.toml",
        ":22:13: campaign.speed_kmh: min 12 is greater than max 3",
    ),
    (
        "run-segments-weight-zero.toml",
        ":22:16: campaign.weights.run_segments: must be greater than 0, found 0",
    ),
    (
        "fault-kind-twice.toml",
        ":22:20: campaign.faults.anchor_range.kinds[1]: `offset` is listed twice",
    ),
    (
        "fault-kind-unknown.toml",
        ":22:20: campaign.faults.anchor_range.kinds[1]: unknown variant `stuck`, expected one of \
         `none`, `bitflip`, `offset`, `amplification`, `set_to`",
    ),
    (
        "wall-without-length.toml",
        ":21:1: environment.walls[0]: the wall's ends a and b coincide",
    ),
    (
        "xml-unknown-route-id.xml",
        ":16:5: route[3].id: unknown route id 9: expected 0 (start route), 1 (recovery route), \
         2 (fence), 3 (ignored) or 4–7 (cutouts)",
    ),
    (
        "xml-missing-fence.xml",
        ": the XML has no route with id 2 (the fence)",
    ),
    (
        "xml-not-a-number.xml",
        ":13:139: fence[2].x: `ten` is not a number",
    ),
    (
        "xml-syntax-error.xml",
        ":15:3: invalid XML: ill-formed document: expected `</routes>`, but `</route>` was found",
    ),
];

#[test]
fn every_malformed_file_is_refused_with_its_message() {
    for (file, expected) in MALFORMED {
        let path = fixtures("malformed").join(file);
        let error = match scenarios::load(&path) {
            Ok(_) => panic!("{file} loaded, but it is malformed"),
            Err(e) => e,
        };
        assert_eq!(
            error.to_string(),
            format!("{}{expected}", path.display()),
            "{file}"
        );
    }
}

#[test]
fn every_malformed_file_has_an_expected_message() {
    let mut on_disk: Vec<String> = std::fs::read_dir(fixtures("malformed"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = MALFORMED.iter().map(|(f, _)| f.to_string()).collect();
    listed.sort();
    assert_eq!(on_disk, listed);
    assert!(listed.len() >= 15);
}

#[test]
fn errors_name_the_field_for_tools() {
    let path = fixtures("malformed").join("anchor-duplicate-id.toml");
    let error = scenarios::load(&path).unwrap_err();
    assert_eq!(error.field(), Some("anchors[2].id"));
    assert!(matches!(
        error.problem,
        scenarios::Problem::DuplicateAnchorId { id: 50, first: 0 }
    ));
}

fn warning_lines(name: &str) -> Vec<String> {
    let loaded = bundled::load(name).unwrap();
    loaded
        .warnings
        .iter()
        .map(|w| format!("{}: {}", w.field, w.kind))
        .collect()
}

const KEPT: &str = "(hand-drawn; kept as drawn)";

#[test]
fn every_bundled_scenario_loads_with_exactly_the_expected_warnings() {
    let turn = |at: &str, deg: &str| {
        format!("{at}: the route turns {deg}° here, more than the generator's 30.0° {KEPT}")
    };
    let seg = |at: &str, i: usize, len: &str| {
        format!("{at}: segment {i} is {len} m long, outside the generator's 0.60–2.00 m {KEPT}")
    };
    let join = |at: &str, len: &str| {
        format!(
            "{at}: the join to start_route[0] is {len} m long, outside the generator's 0.60–2.00 m {KEPT}"
        )
    };
    let no_anchors =
        "anchors: no anchors: UWB positioning cannot be tested in this area".to_owned();
    let expected: [(&str, Vec<String>); 5] = [
        (
            "courtyard",
            vec![
                no_anchors.clone(),
                turn("recovery_route[4]", "51.3"),
                seg("start_route[0]", 0, "2.11"),
                seg("start_route[1]", 1, "2.63"),
            ],
        ),
        (
            "cutouts-four",
            vec![
                no_anchors,
                seg("recovery_route[0]", 0, "3.34"),
                seg("recovery_route[1]", 1, "2.94"),
                seg("recovery_route[2]", 2, "2.31"),
                join("recovery_route[3]", "2.23"),
                seg("start_route[0]", 0, "2.12"),
                seg("start_route[1]", 1, "2.10"),
            ],
        ),
        (
            "parking-lot-2anchors",
            vec![
                turn("recovery_route[1]", "38.8"),
                turn("recovery_route[5]", "31.9"),
                seg("recovery_route[5]", 5, "0.48"),
                turn("recovery_route[7]", "31.0"),
                turn("recovery_route[13]", "36.9"),
                turn("recovery_route[14]", "49.1"),
                join("recovery_route[15]", "0.55"),
            ],
        ),
        ("parking-lot-august", vec![]),
        ("parking-lot-rock", vec![turn("start_route[0]", "38.9")]),
    ];
    assert_eq!(
        bundled::names(),
        expected.iter().map(|(n, _)| *n).collect::<Vec<_>>()
    );
    for (name, warnings) in expected {
        assert_eq!(warning_lines(name), warnings, "{name}");
    }
}

#[test]
fn bundled_scenarios_are_named_and_sourced() {
    for &name in bundled::names() {
        let loaded = bundled::load(name).unwrap();
        assert_eq!(loaded.scenario.name, name);
        assert_eq!(loaded.source, format!("bundled:{name}"));
        assert!(
            bundled::text(name)
                .unwrap()
                .starts_with("# Bundled test area")
        );
    }
    let error = bundled::load("moon").unwrap_err();
    assert_eq!(
        error.to_string(),
        "bundled:moon: no bundled scenario `moon` (known: courtyard, cutouts-four, \
         parking-lot-2anchors, parking-lot-august, parking-lot-rock)"
    );
}

/// The bundled scenario without what was added by hand (description; the rock's environment).
fn as_imported(mut scenario: Scenario) -> Scenario {
    scenario.description = None;
    scenario.environment = Default::default();
    scenario
}

#[test]
fn importing_the_reference_xml_gives_the_bundled_scenario() {
    for &name in bundled::names() {
        let xml = scenarios::load(fixtures("xml").join(format!("{name}.xml"))).unwrap();
        let toml = bundled::load(name).unwrap();
        assert_eq!(xml.scenario, as_imported(toml.scenario.clone()), "{name}");
        let strip = |w: &[scenarios::Warning]| -> Vec<String> {
            w.iter()
                .map(|w| format!("{}: {}", w.field, w.kind))
                .collect()
        };
        assert_eq!(strip(&xml.warnings), strip(&toml.warnings), "{name}");
    }
}

#[test]
fn canonical_toml_round_trips_and_hashes_stably() {
    for &name in bundled::names() {
        let loaded = bundled::load(name).unwrap();
        let text = scenarios::to_toml(&loaded.scenario);
        let again = scenarios::from_toml_str(&text, "again.toml").unwrap();
        assert_eq!(again.scenario, loaded.scenario, "{name}");
        assert_eq!(scenarios::to_toml(&again.scenario), text, "{name}");
        assert_eq!(again.scenario.hash(), loaded.scenario.hash());
    }
    let hashes: Vec<String> = bundled::names()
        .iter()
        .map(|n| bundled::load(n).unwrap().scenario.hash())
        .collect();
    let mut unique = hashes.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(
        unique.len(),
        hashes.len(),
        "different areas, different hashes"
    );
}

fn hidden_by(rock: &Polygon, from: Point, to: Point) -> bool {
    rock.edges()
        .any(|(a, b)| segments_intersect(from, to, a, b))
}

#[test]
fn the_illustrative_rock_hides_anchor_234_from_a_minority_of_the_lot_and_the_wall_reflects() {
    let scenario = bundled::load("parking-lot-rock").unwrap().scenario;
    let env = &scenario.environment;
    assert!(env.obstacles.iter().all(|o| o.illustrative));
    assert!(env.walls.iter().all(|w| w.illustrative));
    let rock = &env.obstacles[0].polygon;
    let (w, h) = rock.bbox().size();
    assert!(
        (0.5..=1.0).contains(&w) && (0.5..=1.0).contains(&h),
        "a rock of 0.5–1 m"
    );
    let anchor = scenario
        .anchors
        .iter()
        .find(|a| a.id == 234)
        .unwrap()
        .position();
    let wall = &env.walls[0];

    // A 0.25 m grid over the drivable area.
    let bbox = scenario.area.bbox();
    let mut drivable = 0usize;
    let mut hidden = 0usize;
    let mut hidden_with_reflection = 0usize;
    let mut behind_wall = 0usize;
    let (cols, rows) = (
        (bbox.size().0 / 0.25) as usize,
        (bbox.size().1 / 0.25) as usize,
    );
    for i in 0..=cols {
        for j in 0..=rows {
            let p = Point::new(bbox.min.x + i as f64 * 0.25, bbox.min.y + j as f64 * 0.25);
            if !scenario.area.contains_point(p) {
                continue;
            }
            drivable += 1;
            behind_wall += usize::from(segments_intersect(p, anchor, wall.a, wall.b));
            if hidden_by(rock, p, anchor) {
                hidden += 1;
                hidden_with_reflection += usize::from(reflects(rock, wall.a, wall.b, p, anchor));
            }
        }
    }
    // A strip of the lot (0.25 m grid: about 3 %) is in the shadow, all of it with a reflection:
    // "a section of the trajectory", crossed by some tests and not by most.
    let share = hidden as f64 / drivable as f64;
    assert!(
        share > 0.02,
        "the rock hides only {:.1} % of the lot",
        share * 100.0
    );
    assert!(
        share < 0.10,
        "the rock hides {:.1} % of the lot",
        share * 100.0
    );
    assert!(hidden_with_reflection as f64 > 0.9 * hidden as f64);
    for p in scenario
        .start_route
        .positions()
        .into_iter()
        .chain(scenario.recovery_route.positions())
    {
        assert!(
            !hidden_by(rock, p, anchor),
            "{p:?}: the start and recovery routes keep line of sight"
        );
    }
    assert_eq!(behind_wall, 0, "the wall itself hides nothing from the lot");
}

/// Whether a one-bounce path `from → wall → to` exists with both legs clear of the rock.
fn reflects(rock: &Polygon, a: Point, b: Point, from: Point, to: Point) -> bool {
    let along = (b - a) * (1.0 / a.dist(b));
    let mirror = |p: Point| {
        let foot = a + along * (p - a).dot(along);
        foot * 2.0 - p
    };
    let image = mirror(to);
    let bounce_line = image - from;
    let denom = bounce_line.cross(b - a);
    if denom == 0.0 {
        return false;
    }
    let t = (a - from).cross(b - a) / denom;
    let s = (a - from).cross(bounce_line) / denom;
    if !(0.0..=1.0).contains(&t) || !(0.0..=1.0).contains(&s) {
        return false;
    }
    let bounce = from + bounce_line * t;
    !hidden_by(rock, from, bounce) && !hidden_by(rock, bounce, to)
}

#[test]
fn the_reference_page_example_loads_without_warnings_and_with_the_defaults() {
    let page = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/scenario-format.md");
    let page = std::fs::read_to_string(page).unwrap();
    let start = page.find("```toml\n").expect("a TOML example") + "```toml\n".len();
    let example = &page[start..start + page[start..].find("```").unwrap()];
    let loaded = scenarios::from_toml_str(example, "example.toml").unwrap();
    assert_eq!(loaded.warnings, []);
    let s = loaded.scenario;
    assert_eq!((s.anchors.len(), s.area.cutouts().len()), (2, 1));
    assert_eq!(s.generator, scenarios::GeneratorSettings::default());
    assert_eq!(s.campaign, scenarios::CampaignSettings::default());
    assert_eq!(s.vehicle, scenarios::Vehicle::default());
}

/// A recovery route that ends far from the start route (7.07 m here) was refused; it is accepted
/// with a warning that names where, and the runner plans the join.
#[test]
fn a_recovery_route_far_from_the_start_route_loads_with_a_planned_join_warning() {
    let path = fixtures("warnings").join("recovery-far-from-start.toml");
    let loaded = scenarios::load(&path).unwrap();
    let warnings: Vec<String> = loaded.warnings.iter().map(ToString::to_string).collect();
    assert!(
        warnings.iter().any(|w| w.ends_with(
            "recovery_route[1]: the recovery route ends 7.07 m from start_route[0], more than \
             3.00 m (1.5 × generator.segment_max_m): the reset plans a route between them"
        )),
        "{warnings:?}"
    );
    assert!(scenarios::needs_planned_join(&loaded.scenario));
}
