//! A structured fuzzer of scenario files: TOML documents built field by field from the extremes
//! of `f64` (±0, subnormals, 1e-300, 1e155, 1e308, `f64::MAX`, `nan`, `inf`), integers beyond
//! their types, very long arrays, duplicated, unknown and missing fields. Loading never panics,
//! and whatever loads goes on without a panic through what `drivecheck area validate` and `run`
//! do with a scenario first: the canonical TOML and its hash, the area's raster and coverage
//! grid, area validation, and a few generator steps after the start route.
//!
//! `SCENARIO_FUZZ_CASES` sets the number of documents (default 256); the test prints how many
//! it ran, how many loaded and how many of those were driven (`--nocapture`).
//! `SCENARIO_FUZZ_SHOW=1` prints why each refused document was refused, and
//! `SCENARIO_FUZZ_SHOW_TEXT=1` the document too.

use std::fmt::Write as _;
use std::sync::atomic::{AtomicUsize, Ordering};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use rand::SeedableRng;
use trajgen::{
    CoverageGrid, Generator, Raster, RouteTail, Strategy as GenStrategy, ValidationConfig,
    validate_area,
};

use crate::from_toml_str;

/// A number as TOML writes it (`nan`, `inf`, `-inf`, `1e155`, `-0.0`).
fn toml_f64(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        // Debug writes every finite f64 as a TOML float (with a `.0` or an exponent), exactly.
        format!("{x:?}")
    }
}

/// The extremes of f64 and some ordinary values, each either sign.
fn extreme() -> impl Strategy<Value = f64> + Clone {
    let special = prop_oneof![
        Just(0.0),
        Just(5e-324),
        Just(f64::MIN_POSITIVE),
        Just(1e-300),
        Just(1e-9),
        Just(1e155),
        Just(1e308),
        Just(f64::MAX),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(100_000.0),
        Just(100_000.000_000_1),
        Just(214_748.4),
        Just(8.333_333_333_333_334),
        Just(30.0),
        Just(180.0),
        Just(1_000.0),
    ];
    (special, any::<bool>()).prop_map(|(x, negative)| if negative { -x } else { x })
}

/// A coordinate or setting: mostly ordinary, often extreme.
fn number(low: f64, high: f64) -> impl Strategy<Value = String> + Clone {
    prop_oneof![
        150 => (low..high).prop_map(toml_f64),
        20 => extreme().prop_map(toml_f64),
        2 => any::<i64>().prop_map(|i| i.to_string()),
        1 => Just("\"7\"".to_owned()),
    ]
}

/// A count: mostly small, at times beyond its type or its limit, negative or a float.
fn count() -> impl Strategy<Value = String> + Clone {
    prop_oneof![
        40 => (0u64..60).prop_map(|i| i.to_string()),
        1 => prop_oneof![
            Just(i64::MAX),
            Just(i64::MIN),
            Just(-1),
            Just(4_294_967_297),
            Just(1_000_001),
            Just(100_001),
        ]
        .prop_map(|i| i.to_string()),
        1 => extreme().prop_map(toml_f64),
    ]
}

/// An interval `{ min, max }` of two counts.
fn count_interval() -> impl Strategy<Value = String> + Clone {
    (count(), count()).prop_map(|(min, max)| format!("{{ min = {min}, max = {max} }}"))
}

/// How a table's fields are mangled.
#[derive(Debug, Clone, Copy)]
enum Mangle {
    Keep,
    Drop,
    Duplicate,
    Unknown,
}

fn mangle() -> impl Strategy<Value = Mangle> {
    prop_oneof![
        400 => Just(Mangle::Keep),
        1 => Just(Mangle::Drop),
        1 => Just(Mangle::Duplicate),
        1 => Just(Mangle::Unknown),
    ]
}

/// An inline table of `fields` (name, value), mangled.
fn inline(fields: &[(&str, String)], how: Mangle) -> String {
    let mut parts: Vec<String> = fields.iter().map(|(k, v)| format!("{k} = {v}")).collect();
    match how {
        Mangle::Keep => {}
        Mangle::Drop => {
            parts.pop();
        }
        Mangle::Duplicate => parts.push(parts[0].clone()),
        Mangle::Unknown => parts.push("z = 1.0".into()),
    }
    format!("{{ {} }}", parts.join(", "))
}

/// One vertex: a base position moved by `delta`, or replaced by an extreme.
fn vertex(base: (f64, f64)) -> BoxedStrategy<String> {
    (
        prop_oneof![40 => Just(None), 1 => number(-1e6, 1e6).prop_map(Some)],
        prop_oneof![40 => Just(None), 1 => number(-1e6, 1e6).prop_map(Some)],
        -0.3f64..0.3,
        mangle(),
    )
        .prop_map(move |(x, y, delta, how)| {
            let x = x.unwrap_or_else(|| toml_f64(base.0 + delta));
            let y = y.unwrap_or_else(|| toml_f64(base.1 - delta));
            inline(&[("x", x), ("y", y)], how)
        })
        .boxed()
}

/// A route point: a base position moved a little or replaced, with a speed.
fn route_point(base: (f64, f64)) -> BoxedStrategy<String> {
    (vertex(base), number(0.2, 8.0), mangle())
        .prop_map(|(xy, speed, how)| {
            let xy = xy
                .trim_start_matches("{ ")
                .trim_end_matches(" }")
                .to_owned();
            match how {
                Mangle::Drop => format!("{{ {xy} }}"),
                Mangle::Duplicate => format!("{{ {xy}, speed = {speed}, speed = 1.0 }}"),
                Mangle::Unknown => format!("{{ {xy}, speed = {speed}, time = 3 }}"),
                Mangle::Keep => format!("{{ {xy}, speed = {speed} }}"),
            }
        })
        .boxed()
}

/// A list: the given items, or (rarely) a very long one around a circle.
fn long_ring(n: usize, centre: (f64, f64), radius: f64, speed: Option<f64>) -> String {
    let mut out = String::from("[");
    for k in 0..n {
        let t = std::f64::consts::TAU * k as f64 / n as f64;
        let (x, y) = (centre.0 + radius * t.cos(), centre.1 + radius * t.sin());
        match speed {
            Some(s) => write!(out, "{{x={x:?},y={y:?},speed={s:?}}},").ok(),
            None => write!(out, "{{x={x:?},y={y:?}}},").ok(),
        };
    }
    out.push(']');
    out
}

/// The fence: the 20 m square (its vertices moved or extreme), or a long ring, or nothing.
fn fence() -> BoxedStrategy<Option<String>> {
    let square = [(0.0, 0.0), (20.0, 0.0), (20.0, 20.0), (0.0, 20.0)];
    prop_oneof![
        30 => square
            .map(vertex)
            .prop_map(|v| Some(format!("fence = [{}]", v.join(", ")))),
        1 => prop_oneof![3usize..2_000, 100_001usize..100_003].prop_map(|n| Some(format!(
            "fence = {}",
            long_ring(n, (10.0, 10.0), 10.0, None)
        ))),
        1 => Just(None),
        1 => Just(Some("fence = []".to_owned())),
    ]
    .boxed()
}

/// A route along `points` (moved or extreme), or a long one, or nothing.
fn route(name: &'static str, points: [(f64, f64); 3]) -> BoxedStrategy<Option<String>> {
    prop_oneof![
        30 => points
            .map(route_point)
            .prop_map(move |p| Some(format!("{name} = [{}]", p.join(", ")))),
        1 => (2usize..5_000).prop_map(move |n| Some(format!(
            "{name} = {}",
            long_ring(n, (10.0, 10.0), 3.0, Some(1.0))
        ))),
        1 => Just(None),
    ]
    .boxed()
}

/// A table `[name]` of `keys`, each present or not (its value from the key's strategy), the whole
/// table at times written twice.
fn section(
    name: &'static str,
    keys: Vec<(&'static str, BoxedStrategy<String>)>,
) -> BoxedStrategy<String> {
    let fields: Vec<_> = keys
        .into_iter()
        .map(|(k, value)| prop::option::weighted(0.3, value).prop_map(move |v| (k, v)))
        .collect();
    (fields, prop::bool::weighted(0.01))
        .prop_map(move |(fields, twice)| {
            let body: String = fields
                .iter()
                .filter_map(|(k, v)| v.as_ref().map(|v| format!("{k} = {v}\n")))
                .collect();
            let once = format!("[{name}]\n{body}");
            if twice && !body.is_empty() {
                format!("{once}{once}")
            } else {
                once
            }
        })
        .boxed()
}

/// Every key of `keys` with numbers from `value`.
fn keys_of(
    keys: &[&'static str],
    value: impl Strategy<Value = String> + Clone + 'static,
) -> Vec<(&'static str, BoxedStrategy<String>)> {
    keys.iter().map(|&k| (k, value.clone().boxed())).collect()
}

/// An interval `{ min, max }` of two numbers.
fn interval() -> impl Strategy<Value = String> + Clone {
    (number(-10.0, 40.0), number(-10.0, 40.0))
        .prop_map(|(min, max)| format!("{{ min = {min}, max = {max} }}"))
}

/// Anchors: none, a few (ids beyond a byte, extreme positions), or more than the firmware keeps.
fn anchors() -> BoxedStrategy<String> {
    let id = prop_oneof![
        40 => 0i64..256,
        1 => any::<i64>(),
        1 => Just(256i64),
        1 => Just(-1i64),
    ];
    let one = (
        id,
        number(-50.0, 50.0),
        number(-50.0, 50.0),
        number(0.0, 5.0),
    )
        .prop_map(|(id, x, y, h)| {
            format!("[[anchors]]\nid = {id}\nx = {x}\ny = {y}\nheight = {h}\n")
        });
    prop_oneof![
        8 => prop::collection::vec(one.clone(), 0..4),
        1 => prop::collection::vec(one, 18..24),
    ]
    .prop_map(|a| a.concat())
    .boxed()
}

/// The environment: an obstacle polygon and a wall, with extreme coordinates at times.
fn environment() -> BoxedStrategy<String> {
    (
        prop::option::of([(30.0, 30.0), (31.0, 30.0), (31.0, 31.0)].map(vertex)),
        prop::option::of((vertex((-5.0, 0.0)), vertex((-5.0, 8.0)))),
    )
        .prop_map(|(obstacle, wall)| {
            let mut out = String::new();
            if let Some(p) = obstacle {
                out += &format!(
                    "[[environment.obstacles]]\nname = \"rock\"\npolygon = [{}]\n",
                    p.join(", ")
                );
            }
            if let Some((a, b)) = wall {
                out += &format!("[[environment.walls]]\nname = \"wall\"\na = {a}\nb = {b}\n");
            }
            out
        })
        .boxed()
}

/// A whole document.
fn document() -> BoxedStrategy<String> {
    let top = (
        fence(),
        prop::option::weighted(
            0.2,
            [(12.0, 12.0), (13.0, 12.0), (13.0, 13.0)]
                .map(vertex)
                .prop_map(|c| format!("cutouts = [[{}]]", c.join(", "))),
        ),
        route("start_route", [(4.0, 4.0), (5.5, 4.0), (7.0, 4.0)]),
        route("recovery_route", [(4.0, 8.5), (4.0, 7.0), (4.0, 5.2)]),
        prop::option::weighted(
            0.15,
            (
                number(-90.0, 90.0),
                number(-180.0, 180.0),
                number(0.0, 500.0),
            ),
        ),
        prop::bool::weighted(0.01),
    );
    let settings = (
        section(
            "generator",
            [
                keys_of(
                    &["segment_min_m", "segment_max_m", "clearance_m"],
                    number(0.0, 3.0),
                ),
                keys_of(&["max_turn_deg"], number(0.0, 90.0)),
                keys_of(
                    &[
                        "ahead_margin",
                        "recovery_ahead_margin",
                        "inner_tries",
                        "outer_tries",
                    ],
                    count(),
                ),
            ]
            .concat(),
        ),
        section(
            "vehicle",
            keys_of(
                &["wheelbase_m", "max_steering_angle_rad", "width_m"],
                number(0.0, 2.0),
            ),
        ),
        section(
            "campaign",
            [
                keys_of(&["oracle_threshold_m"], number(0.0, 5.0)),
                keys_of(&["tests"], count()),
                keys_of(&["test_size", "points_per_segment"], count_interval()),
                keys_of(&["speed_kmh"], interval()),
            ]
            .concat(),
        ),
        section(
            "campaign.faults.yaw",
            keys_of(
                &["offset_deg", "set_to_deg", "amplification", "bitflip_bits"],
                interval(),
            ),
        ),
        anchors(),
        environment(),
    );
    (top, settings)
        .prop_map(
            |(
                (fence, cutouts, start, recovery, origin, duplicate_fence),
                (generator, vehicle, campaign, faults, anchors, environment),
            )| {
                let mut doc = String::from("name = \"fuzz\"\n");
                for line in [&fence, &cutouts, &start, &recovery].into_iter().flatten() {
                    doc += line;
                    doc += "\n";
                }
                if duplicate_fence && let Some(fence) = &fence {
                    doc += fence;
                    doc += "\n";
                }
                doc += &anchors;
                if let Some((lat, lon, height)) = origin {
                    doc += &format!("[origin]\nlat = {lat}\nlon = {lon}\nheight = {height}\n");
                }
                for s in [generator, vehicle, campaign, faults, environment] {
                    doc += &s;
                }
                doc
            },
        )
        .boxed()
}

/// `s` with the ranges of the kinds a fault section neither lists nor has by default set to
/// their defaults: the canonical TOML leaves those out (so that a new kind in the fault table
/// leaves every hash unchanged), so a file that gives one loads to a scenario its canonical TOML
/// does not give back. They are never drawn; the fuzzer found it, the report says so.
fn unlisted_ranges_as_default(s: &crate::Scenario) -> crate::Scenario {
    use crate::{FaultKind, FaultTarget, ProbeFaults};
    let mut s = s.clone();
    for target in FaultTarget::ALL {
        let defaults = ProbeFaults::defaults(target);
        let section = s.campaign.faults.get_mut(target);
        for kind in FaultKind::drawable() {
            if !section.kinds.contains(&kind) && !defaults.kinds.contains(&kind) {
                section.ranges.insert(kind, defaults.range(kind));
            }
        }
    }
    s
}

/// A valid scenario, each of its numbers a slot `@k@` with its value here.
const TEMPLATE: &str = "name = \"tame\"
fence = [{ x = @0@, y = @1@ }, { x = @2@, y = 0.0 }, { x = 20.0, y = @3@ }, { x = 0.0, y = 20.0 }]
cutouts = [[{ x = @4@, y = 12.0 }, { x = 13.0, y = 12.0 }, { x = 13.0, y = @5@ }]]
start_route = [{ x = @6@, y = 4.0, speed = @7@ }, { x = 5.5, y = @8@, speed = 1.0 }, { x = 7.0, y = 4.0, speed = 1.0 }]
recovery_route = [{ x = 4.0, y = 8.5, speed = 1.0 }, { x = @9@, y = 7.0, speed = 1.0 }, { x = 4.0, y = @10@, speed = @11@ }]
[[anchors]]
id = 1
x = @12@
y = @13@
height = @14@
[[environment.obstacles]]
name = \"rock\"
polygon = [{ x = @15@, y = 30.0 }, { x = 31.0, y = 30.0 }, { x = 31.0, y = 31.0 }]
[[environment.walls]]
name = \"wall\"
a = { x = -5.0, y = @16@ }
b = { x = -5.0, y = 8.0 }
[origin]
lat = @17@
lon = @18@
height = @19@
[vehicle]
wheelbase_m = @20@
width_m = @21@
[generator]
segment_min_m = @22@
segment_max_m = @23@
max_turn_deg = @24@
clearance_m = @25@
[campaign]
oracle_threshold_m = @26@
speed_kmh = { min = @27@, max = @28@ }
[campaign.faults.yaw]
offset_deg = { min = @29@, max = @30@ }
[campaign.faults.anchor_range]
amplification = { min = @31@, max = @32@ }
";

/// The template's values.
const TAME: [f64; 33] = [
    0.0, 0.0, 20.0, 20.0, 12.0, 13.0, 4.0, 1.0, 4.0, 4.0, 5.2, 1.0, -3.0, 25.0, 1.5, 30.0, 0.0,
    61.45, 23.85, 120.0, 0.475, 0.5, 0.6, 2.0, 30.0, 0.5, 1.0, 3.0, 12.0, -20.0, 20.0, 0.0, 5.0,
];

/// The valid template with one or two of its numbers replaced by extremes, or moved a little:
/// documents that mostly load, so that the extremes that are accepted reach the generator.
fn tame_document() -> BoxedStrategy<String> {
    let change = (
        0..TAME.len(),
        prop_oneof![3 => extreme(), 1 => -1e-3f64..1e-3],
    );
    prop::collection::vec(change, 1..3)
        .prop_map(|changes| {
            let mut values = TAME;
            for (slot, value) in changes {
                values[slot] = if value.abs() < 1e-3 && value != 0.0 {
                    values[slot] + value
                } else {
                    value
                };
            }
            let mut text = TEMPLATE.to_owned();
            for (k, v) in values.iter().enumerate() {
                text = text.replace(&format!("@{k}@"), &toml_f64(*v));
            }
            text
        })
        .boxed()
}

static LOADED: AtomicUsize = AtomicUsize::new(0);
static DRIVEN: AtomicUsize = AtomicUsize::new(0);

/// What `area validate` and `run` do with a loaded scenario first, with the generator's tries
/// bounded (the file's may be 100,000 × 10,000 per extension: time, not a panic).
fn drive(text: &str) -> Result<(), TestCaseError> {
    let loaded = match from_toml_str(text, "fuzz.toml") {
        Ok(loaded) => loaded,
        Err(error) => {
            if std::env::var_os("SCENARIO_FUZZ_SHOW").is_some() {
                eprintln!("{error}");
                if std::env::var_os("SCENARIO_FUZZ_SHOW_TEXT").is_some() {
                    eprintln!("{text}\n----");
                }
            }
            return Ok(());
        }
    };
    LOADED.fetch_add(1, Ordering::Relaxed);
    let s = &loaded.scenario;
    // The canonical TOML loads back to the same scenario.
    let again = from_toml_str(&s.to_toml(), "again.toml").map_err(|e| {
        TestCaseError::fail(format!("canonical TOML refused: {e}\n{}", s.to_toml()))
    })?;
    prop_assert_eq!(again.scenario.to_toml(), s.to_toml());
    prop_assert_eq!(&again.scenario, &unlisted_ranges_as_default(s));
    prop_assert!(s.area.drivable_area().is_finite() && s.area.drivable_area() > 0.0);
    let _ = s.hash();
    let raster = Raster::new(&s.area, 0.5);
    prop_assert!(raster.cols * raster.rows <= trajgen::raster::MAX_CELLS);
    let mut grid = CoverageGrid::new(&s.area, 0.5);
    let start = s.start_route.positions();
    for w in start.windows(2) {
        grid.visit_segment(w[0], w[1]);
    }
    let mut config = s.generator.generator_config(GenStrategy::default());
    config.outer_tries = config.outer_tries.min(20);
    config.inner_tries = config.inner_tries.min(20);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
    let validation = ValidationConfig {
        extension_points: 5,
        max_failures: 3,
        ..ValidationConfig::default()
            .with_km(0.02)
            .with_generator(config)
    };
    let _ = validate_area(&s.area, &start, &validation, &mut rng, &mut |_| {});
    if let (Ok(generator), Ok(mut tail)) = (Generator::new(config), RouteTail::from_points(&start))
    {
        for _ in 0..3 {
            let Ok(extension) = generator.extend(&s.area, &tail, 5, &mut rng) else {
                break;
            };
            tail = tail.advanced(&extension.points);
        }
    }
    let _ = crate::needs_planned_join(s);
    DRIVEN.fetch_add(1, Ordering::Relaxed);
    Ok(())
}

#[test]
fn scenario_files_of_extreme_values_never_panic_and_what_loads_can_be_driven() {
    let cases = std::env::var("SCENARIO_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256);
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    let ran = AtomicUsize::new(0);
    let documents = prop_oneof![document(), tame_document()];
    let result = runner.run(&documents, |text| {
        ran.fetch_add(1, Ordering::Relaxed);
        drive(&text)
    });
    eprintln!(
        "scenario fuzz: {} documents run, {} loaded, {} driven",
        ran.load(Ordering::Relaxed),
        LOADED.load(Ordering::Relaxed),
        DRIVEN.load(Ordering::Relaxed)
    );
    if let Err(error) = result {
        panic!("{error}");
    }
}
