//! `drivecheck-dev bench fidelity` end to end, small: the tables, every published segment with its
//! simulated distribution, the rock lot's shares, and the route following on the published circle
//! next to the real car's recordings; on the firmware built for the host (`--car sitl:TREE`, the
//! tree from `DRIVECHECK_FIRMWARE_10`: without it the test says `skipped: no firmware tree`, and
//! fails under `CI=true`).

use crate::common;

use common::{drivecheck, text};

#[test]
fn the_fidelity_benchmark_prints_the_published_sequence_and_the_rock_lot() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("rock.svg");
    let out = drivecheck(&[
        "bench",
        "fidelity",
        "--tests",
        "3",
        "--reruns",
        "2",
        "--rock-tests",
        "4",
        "--svg",
        common::path(&svg),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout
            .contains("parking-lot-august driven by the embedded simulated car: 3 generated tests"),
        "{stdout}"
    );
    for row in [
        "| 1 segment 1 | 0.47–0.47 |",
        "| 3 after the wheel slip | 0.69–0.73 |",
        "| 5 after the four faults | 1.47–1.77 |",
    ] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(row))
            .unwrap_or_else(|| panic!("{row}: {stdout}"));
        // Three simulated maxima per distribution, each a number of metres.
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let values: Vec<f64> = cells[3].split(" / ").map(|v| v.parse().unwrap()).collect();
        assert_eq!(values.len(), 3, "{line}");
        assert!(values.windows(2).all(|w| w[0] <= w[1]), "{line}");
        assert!(values.iter().all(|v| (0.05..5.0).contains(v)), "{line}");
        assert!(cells[4].ends_with("/3"), "{line}");
    }
    let tests = stdout
        .lines()
        .find(|l| l.starts_with("| tests |"))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(tests.contains("/4 |"), "{tests}");
    // The picture: four driven tracks, the rock and the wall, and a red dot per sample above 1 m
    // as its legend counts them.
    let picture = std::fs::read_to_string(&svg).unwrap();
    assert!(picture.starts_with("<svg") && picture.trim_end().ends_with("</svg>"));
    assert_eq!(picture.matches("stroke=\"#888\"").count(), 4);
    assert!(picture.contains("<title>rock</title>") && picture.contains("reflecting wall"));
    let dots = picture.matches("<circle").count();
    assert!(
        picture.contains(&format!("red: {dots} of ")),
        "{dots} dots, legend: {}",
        picture.lines().rev().nth(1).unwrap_or_default()
    );
}

/// The route-following table's row `name`: the real car's figure and the simulated runs' median,
/// min and max.
fn route_row(stdout: &str, name: &str) -> (f64, [f64; 3]) {
    let line = stdout
        .lines()
        .find(|l| l.starts_with(&format!("| {name} |")))
        .unwrap_or_else(|| panic!("{name}: {stdout}"));
    let cells: Vec<&str> = line.split('|').map(str::trim).collect();
    let real = cells[2].parse().unwrap();
    // "p50 (min–max)"
    let sim: Vec<f64> = cells[3]
        .split(['(', '–', ')'])
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().unwrap())
        .collect();
    assert_eq!(sim.len(), 3, "{line}");
    assert!(sim[1] <= sim[0] && sim[0] <= sim[2], "{line}");
    (real, [sim[0], sim[1], sim[2]])
}

#[test]
fn the_default_simulator_follows_the_published_circle_like_the_real_car() {
    let out = drivecheck(&[
        "bench",
        "fidelity",
        "--tests",
        "1",
        "--reruns",
        "1",
        "--rock-tests",
        "1",
        "--route-runs",
        "5",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("the real car and 5 simulated runs") && stdout.contains("8b9c36a"),
        "{stdout}"
    );
    // The real column is computed from the bundled recordings: the figures (fused vs
    // each fix p50 1.2 cm; distance to the route p95 3.9 cm, 0.4 cm per 100 ms, 0.6 s).
    let diff_p50 = route_row(&stdout, "GNSS fix vs fused history p50 (cm)");
    let diff_p95 = route_row(&stdout, "GNSS fix vs fused history p95 (cm)");
    let route_p50 = route_row(&stdout, "distance to the route p50 (cm)");
    let route_p95 = route_row(&stdout, "distance to the route p95 (cm)");
    let change = route_row(&stdout, "change of the distance per 100 ms, mean (cm)");
    let correlation = route_row(&stdout, "correlation time of the distance (s)");
    assert!((diff_p50.0 - 1.2).abs() < 0.05, "{diff_p50:?}");
    assert!((route_p95.0 - 3.9).abs() < 0.05, "{route_p95:?}");
    assert!((change.0 - 0.4).abs() < 0.05, "{change:?}");
    assert!((correlation.0 - 0.6).abs() < 0.05, "{correlation:?}");
    // The default simulator (its GNSS noise fitted to these recordings) within stated
    // tolerances of the real car, on the median of its runs.
    let within = |(real, sim): (f64, [f64; 3]), abs: f64| (sim[0] - real).abs() <= abs;
    let factor = |(real, sim): (f64, [f64; 3]), f: f64| sim[0] <= real * f && sim[0] >= real / f;
    assert!(within(diff_p50, 0.4), "fix vs history p50 {diff_p50:?}");
    assert!(within(diff_p95, 0.8), "fix vs history p95 {diff_p95:?}");
    assert!(within(route_p50, 0.6), "route p50 {route_p50:?}");
    assert!(within(route_p95, 1.0), "route p95 {route_p95:?}");
    assert!(factor(change, 1.5), "change per 100 ms {change:?}");
    assert!(factor(correlation, 1.5), "correlation time {correlation:?}");
}

#[test]
fn on_the_firmware_built_for_the_host_the_fidelity_benchmark_drives_the_published_sequence() {
    let Some(tree) = std::env::var("DRIVECHECK_FIRMWARE_10")
        .ok()
        .filter(|v| !v.is_empty())
    else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true and no firmware tree: set DRIVECHECK_FIRMWARE_10"
        );
        println!("skipped: no firmware tree");
        return;
    };
    let car = format!("sitl:{tree}");
    let out = drivecheck(&[
        "bench",
        "fidelity",
        "--car",
        &car,
        "--tests",
        "2",
        "--reruns",
        "2",
        "--rock-tests",
        "2",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("parking-lot-august driven by the firmware 10.1 built for the host (tree "),
        "{stdout}"
    );
    // The four faults, through the firmware's own fault injection, raise the last segment above
    // the same segment without them in each test.
    let line = stdout
        .lines()
        .find(|l| l.starts_with("| 5 after the four faults | 1.47–1.77 |"))
        .unwrap_or_else(|| panic!("{stdout}"));
    let cells: Vec<&str> = line.split('|').map(str::trim).collect();
    let number =
        |cell: &str| -> Vec<f64> { cell.split(" / ").map(|v| v.parse().unwrap()).collect() };
    let (with, without) = (number(cells[3]), number(cells[7]));
    assert!(with[0] > without[2], "{line}");
    assert!(
        stdout.contains("| tests |") && stdout.contains("/2 |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("## Route following: measured on the embedded simulated car only"),
        "{stdout}"
    );
}
