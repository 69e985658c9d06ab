//! `drivecheck-dev bench placement` end to end, small: a row per firmware generation, every fault the
//! simulated cars added behind a 150 ± 40 ms link measured, and each within 0.2 m of its place.

use crate::common;

use common::{drivecheck, text};

#[test]
fn the_placement_benchmark_measures_every_fault_on_both_firmwares() {
    let out = drivecheck(&[
        "bench",
        "placement",
        "--seeds",
        "1",
        "--link-seeds",
        "1",
        "--tests",
        "4",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("one-way latency 150ms + up to 40ms"),
        "{stdout}"
    );
    for firmware in ["10.1", "12.3"] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("| {firmware} |")))
            .unwrap_or_else(|| panic!("{firmware}: {stdout}"));
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let count = |i: usize| cells[i].parse::<usize>().unwrap();
        let (faults, unmeasured, within) = (count(2), count(3), count(5));
        assert!(faults > 5, "{line}");
        assert_eq!(unmeasured, 0, "{line}");
        assert_eq!(within, faults, "{line}");
        let largest: f64 = cells[8].parse().unwrap();
        assert!((0.0..=0.2).contains(&largest), "{line}");
    }
}
