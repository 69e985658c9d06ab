//! `drivecheck bench fidelity` end to end, small: both tables, every published segment with its
//! simulated distribution, and the rock lot's shares.

mod common;

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
        stdout.contains("parking-lot-august: 3 generated tests"),
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
