//! Writes a scenario as canonical TOML: every field explicit, a fixed order, one point per line.
//!
//! The output loads back to the same [`Scenario`] (floats are written in Rust's shortest
//! round-trip form) and is what [`Scenario::hash`] hashes.

use std::fmt::Write as _;

use trajgen::Point;

use crate::model::{Anchor, Obstacle, Route, Scenario, Wall};
use crate::settings::{
    CampaignSettings, FaultKind, FaultTarget, GeneratorSettings, Interval, ProbeFaults,
    SHARED_PARAM_KEY, Vehicle,
};
use car_link::firmware::Param;

/// The scenario in canonical TOML.
pub fn to_toml(s: &Scenario) -> String {
    let mut out = String::new();
    out.push_str("# drivecheck scenario; the format is described in docs/scenario-format.md\n");
    line(&mut out, "name", &string(&s.name));
    if let Some(description) = &s.description {
        line(&mut out, "description", &string(description));
    }
    out.push('\n');
    point_list(&mut out, "fence", s.area.fence().vertices(), "");
    write_cutouts(&mut out, s.area.cutouts());
    route(&mut out, "start_route", &s.start_route);
    route(&mut out, "recovery_route", &s.recovery_route);
    if let Some(origin) = &s.origin {
        out.push_str("\n[origin]\n");
        line(&mut out, "lat", &float(origin.lat));
        line(&mut out, "lon", &float(origin.lon));
        line(&mut out, "height", &float(origin.height));
    }
    s.anchors.iter().for_each(|a| anchor(&mut out, a));
    s.environment
        .obstacles
        .iter()
        .for_each(|o| obstacle(&mut out, o));
    s.environment.walls.iter().for_each(|w| wall(&mut out, w));
    vehicle(&mut out, &s.vehicle);
    generator(&mut out, &s.generator);
    campaign(&mut out, &s.campaign);
    out
}

/// A TOML float literal that reads back to exactly `value`.
fn float(value: f64) -> String {
    if value.is_nan() {
        "nan".into()
    } else if value.is_infinite() {
        if value > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        }
    } else {
        format!("{value:?}")
    }
}

/// A TOML basic string literal.
fn string(text: &str) -> String {
    toml::Value::String(text.to_owned()).to_string()
}

fn line(out: &mut String, key: &str, value: &str) {
    let _ = writeln!(out, "{key} = {value}");
}

fn xy(p: Point) -> String {
    format!("{{ x = {}, y = {} }}", float(p.x), float(p.y))
}

fn point_list(out: &mut String, key: &str, points: &[Point], indent: &str) {
    let _ = writeln!(out, "{indent}{key} = [");
    for &p in points {
        let _ = writeln!(out, "{indent}    {},", xy(p));
    }
    let _ = writeln!(out, "{indent}]");
}

fn write_cutouts(out: &mut String, cutouts: &[trajgen::Polygon]) {
    if cutouts.is_empty() {
        out.push_str("cutouts = []\n");
        return;
    }
    out.push_str("cutouts = [\n");
    for cutout in cutouts {
        out.push_str("    [\n");
        for &p in cutout.vertices() {
            let _ = writeln!(out, "        {},", xy(p));
        }
        out.push_str("    ],\n");
    }
    out.push_str("]\n");
}

fn route(out: &mut String, key: &str, route: &Route) {
    let _ = writeln!(out, "{key} = [");
    for p in &route.points {
        let _ = writeln!(
            out,
            "    {{ x = {}, y = {}, speed = {} }},",
            float(p.position.x),
            float(p.position.y),
            float(p.speed)
        );
    }
    out.push_str("]\n");
}

fn anchor(out: &mut String, a: &Anchor) {
    out.push_str("\n[[anchors]]\n");
    line(out, "id", &a.id.to_string());
    line(out, "x", &float(a.x));
    line(out, "y", &float(a.y));
    line(out, "height", &float(a.height));
}

fn obstacle(out: &mut String, o: &Obstacle) {
    out.push_str("\n[[environment.obstacles]]\n");
    line(out, "name", &string(&o.name));
    line(out, "illustrative", &o.illustrative.to_string());
    point_list(out, "polygon", o.polygon.vertices(), "");
}

fn wall(out: &mut String, w: &Wall) {
    out.push_str("\n[[environment.walls]]\n");
    line(out, "name", &string(&w.name));
    line(out, "illustrative", &w.illustrative.to_string());
    line(out, "a", &xy(w.a));
    line(out, "b", &xy(w.b));
}

fn vehicle(out: &mut String, v: &Vehicle) {
    out.push_str("\n[vehicle]\n");
    line(out, "wheelbase_m", &float(v.wheelbase_m));
    line(
        out,
        "max_steering_angle_rad",
        &float(v.max_steering_angle_rad),
    );
    line(out, "width_m", &float(v.width_m));
}

fn generator(out: &mut String, g: &GeneratorSettings) {
    out.push_str("\n[generator]\n");
    line(out, "segment_min_m", &float(g.segment_min_m));
    line(out, "segment_max_m", &float(g.segment_max_m));
    line(out, "max_turn_deg", &float(g.max_turn_deg));
    line(out, "ahead_margin", &g.ahead_margin.to_string());
    line(
        out,
        "recovery_ahead_margin",
        &g.recovery_ahead_margin.to_string(),
    );
    line(out, "inner_tries", &g.inner_tries.to_string());
    line(out, "outer_tries", &g.outer_tries.to_string());
    line(out, "clearance_m", &float(g.clearance_m));
}

fn floats(i: Interval<f64>) -> String {
    format!("{{ min = {}, max = {} }}", float(i.min), float(i.max))
}

fn ints<T: std::fmt::Display>(i: Interval<T>) -> String {
    format!("{{ min = {}, max = {} }}", i.min, i.max)
}

fn campaign(out: &mut String, c: &CampaignSettings) {
    out.push_str("\n[campaign]\n");
    line(out, "tests", &c.tests.to_string());
    line(out, "test_size", &ints(c.test_size));
    line(out, "points_per_segment", &ints(c.points_per_segment));
    line(out, "speed_kmh", &floats(c.speed_kmh));
    line(out, "oracle_threshold_m", &float(c.oracle_threshold_m));
    out.push_str("\n[campaign.weights]\n");
    line(out, "run_segments", &c.weights.run_segments.to_string());
    line(
        out,
        "anchor_range_fault",
        &c.weights.anchor_range_fault.to_string(),
    );
    line(
        out,
        "wheel_slip_fault",
        &c.weights.wheel_slip_fault.to_string(),
    );
    line(out, "yaw_fault", &c.weights.yaw_fault.to_string());
    for target in FaultTarget::ALL {
        probe_faults(out, target, c.faults.get(target));
    }
}

// The canonical form writes a section's default kinds' ranges always and another kind's only
// when it is listed (and a section's kinds only when they are not its default, except
// anchor_range's, always written as the format began), so that adding a kind to the fault table
// leaves the hash of every scenario that does not use it unchanged. anchor_range writes offset
// and amplification as one `param` while their ranges are equal, as the format began.

fn probe_faults(out: &mut String, target: FaultTarget, f: &ProbeFaults) {
    let _ = writeln!(out, "\n[campaign.faults.{}]", target.section());
    let defaults = target.default_kinds();
    if target == FaultTarget::AnchorRange || f.kinds != defaults {
        let names: Vec<String> = f.kinds.iter().map(|k| string(k.name())).collect();
        line(out, "kinds", &format!("[{}]", names.join(", ")));
    }
    let shared = f.shares_param(target);
    if shared {
        line(out, SHARED_PARAM_KEY, &floats(f.range(FaultKind::Offset)));
    }
    let written = defaults
        .iter()
        .copied()
        .filter(|_| !shared)
        .chain(FaultKind::drawable().filter(|k| !defaults.contains(k) && f.kinds.contains(k)));
    for kind in written {
        if let Some(key) = target.key(kind) {
            let range = f.range(kind);
            let value = match kind.spec().param {
                Param::Bit => bits(range),
                Param::Value | Param::Factor | Param::Unused => floats(range),
            };
            line(out, &key, &value);
        }
    }
    line(out, "start", &ints(f.start));
    line(out, "duration", &ints(f.duration));
}

/// A range of bit numbers: integers (a value that is not one, which validation refuses, as a
/// float so that it reads back).
fn bits(range: Interval<f64>) -> String {
    let int = |x: f64| {
        if x.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(&x) {
            format!("{}", x as u32)
        } else {
            float(x)
        }
    };
    format!("{{ min = {}, max = {} }}", int(range.min), int(range.max))
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use trajgen::{Area, Point, Polygon, Waypoint};

    use super::*;
    use crate::model::{EnuOrigin, Environment};
    use crate::raw::{build, parse_toml};

    #[test]
    fn floats_are_toml_literals_that_read_back_exactly() {
        assert_eq!(float(1.0), "1.0");
        assert_eq!(float(-0.0), "-0.0");
        assert_eq!(float(1e-7), "1e-7");
        assert_eq!(float(f64::NAN), "nan");
        assert_eq!(float(f64::NEG_INFINITY), "-inf");
        let text = "a \"b\" 'c'\n\\";
        let table: toml::Table = toml::from_str(&format!("s = {}", string(text))).unwrap();
        assert_eq!(table["s"].as_str(), Some(text));
    }

    fn finite() -> impl Strategy<Value = f64> {
        prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO
    }

    fn route(points: &[(f64, f64)], shift: Point, speed: f64) -> Route {
        let points = points
            .iter()
            .map(|&(x, y)| Waypoint::new(Point::new(x + shift.x, y + shift.y), speed))
            .collect();
        Route { points }
    }

    fn scenario(
        shift: Point,
        numbers: [f64; 6],
        counts: [usize; 3],
        name: String,
    ) -> Option<Scenario> {
        let square = [(0., 0.), (10., 0.), (10., 10.), (0., 10.)];
        let fence = Polygon::new(
            square
                .iter()
                .map(|&(x, y)| Point::new(x, y) + shift)
                .collect(),
        )
        .ok()?;
        let tri = [(6., 6.), (7., 6.), (7., 7.)];
        let cutout =
            Polygon::new(tri.iter().map(|&(x, y)| Point::new(x, y) + shift).collect()).ok()?;
        let area = Area::new(fence, vec![cutout]).ok()?;
        let mut s = Scenario {
            name,
            description: Some("round \"trip\"".into()),
            origin: Some(EnuOrigin {
                lat: numbers[0],
                lon: numbers[1],
                height: numbers[2],
            }),
            area,
            start_route: route(&[(2., 2.), (3.5, 2.)], shift, numbers[3]),
            recovery_route: route(&[(2., 6.), (2., 4.5)], shift, numbers[3]),
            // Any finite number within the coordinates' bound (subnormals and -0 kept).
            anchors: vec![Anchor {
                id: 255,
                x: numbers[4] % crate::limits::MAX_COORDINATE_M,
                y: numbers[5] % crate::limits::MAX_COORDINATE_M,
                height: 1.0,
            }],
            environment: Environment::default(),
            vehicle: Vehicle {
                width_m: numbers[4],
                ..Vehicle::default()
            },
            generator: GeneratorSettings::default(),
            campaign: CampaignSettings::default(),
        };
        s.generator.segment_max_m = numbers[5];
        s.generator.outer_tries = counts[0];
        s.campaign.test_size = Interval::new(counts[1], counts[2]);
        let faults = &mut s.campaign.faults;
        faults
            .yaw
            .ranges
            .insert(FaultKind::Offset, Interval::new(numbers[0], numbers[1]));
        // Every kind listed, and anchor ranges that no longer share one `param` when the numbers
        // differ.
        faults.wheel_slip.kinds = FaultKind::drawable().collect();
        faults
            .wheel_slip
            .ranges
            .insert(FaultKind::SetTo, Interval::new(numbers[2], numbers[3]));
        faults.wheel_slip.ranges.insert(
            FaultKind::Bitflip,
            Interval::new((counts[0] % 32) as f64, (counts[1] % 32) as f64),
        );
        faults.anchor_range.ranges.insert(
            FaultKind::Amplification,
            Interval::new(numbers[4], numbers[5]),
        );
        Some(s)
    }

    proptest! {
        #[test]
        fn canonical_toml_reads_back_to_the_same_scenario(
            dx in -9e4..9e4f64,
            dy in -9e4..9e4f64,
            numbers in prop::array::uniform6(finite()),
            counts in prop::array::uniform3(0usize..100_000),
            name in "\\PC{0,20}",
        ) {
            let Some(s) = scenario(Point::new(dx, dy), numbers, counts, name) else {
                return Ok(());
            };
            let text = to_toml(&s);
            let raw = parse_toml(&text, "p.toml").map_err(|e| TestCaseError::fail(e.to_string()))?;
            let again = build(raw, "p.toml").map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(&again, &s);
            prop_assert_eq!(again.hash(), s.hash());
        }
    }

    #[test]
    fn the_hash_changes_with_any_setting() {
        let s = scenario(Point::new(0.0, 0.0), [1.0; 6], [5; 3], "h".into()).unwrap();
        let mut t = s.clone();
        t.campaign.weights.yaw_fault += 1;
        assert_eq!(s.hash().len(), 64);
        assert!(s.hash().chars().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(s.hash(), t.hash());
    }
}
