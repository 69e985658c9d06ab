//! `drivecheck sweep`: a case driven for every value of a parameter, deterministically given the
//! seed; the correction clamp's trade-off of the method (a larger clamp helps against wheel
//! slip, a smaller one against reflections) shows in the simulated car.

use crate::common;

use std::path::{Path, PathBuf};

use campaign::sweep::SweepReport;
use common::{drivecheck, path, text};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn sweep(case: &Path, sets: &[&str]) -> SweepReport {
    let mut args = vec!["sweep", path(case), "--runs", "2", "--seed", "1", "--json"];
    for set in sets {
        args.extend_from_slice(&["--set", set]);
    }
    let run = drivecheck(&args);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run));
    let printed: serde_json::Value =
        serde_json::from_slice(&run.stdout).expect("sweep --json prints one document");
    assert_eq!(printed["command"], "sweep", "{printed:#}");
    serde_json::from_value(printed["sweep"].clone()).expect("its `sweep` is a sweep report")
}

/// Runs that failed and the median of segment 3's largest deviation, per clamp value.
fn by_clamp(report: &SweepReport) -> Vec<(f64, usize, f64)> {
    report
        .points
        .iter()
        .map(|p| {
            (
                p.values[0],
                p.failed_runs(),
                p.segments[3].median_max_m.expect("segment 3 was judged"),
            )
        })
        .collect()
}

#[test]
fn the_correction_clamp_trades_wheel_slip_against_reflections() {
    // Both cases drive the same six segments with one fault placed at the start of segment 3.
    let reflection = sweep(
        &fixture("placed-reflection.json"),
        &["sim.uwb_clamp_m=0.1,0.4"],
    );
    let slip = sweep(
        &fixture("placed-wheel-slip.json"),
        &["sim.uwb_clamp_m=0.1,0.4"],
    );
    let (reflection, slip) = (by_clamp(&reflection), by_clamp(&slip));
    // A reflection (range amplification on anchor 234): the small clamp keeps the estimate in,
    // the large one follows the wrong range.
    assert_eq!(reflection[0].1, 0, "{reflection:?}");
    assert_eq!(reflection[1].1, 2, "{reflection:?}");
    assert!(
        reflection[0].2 < 1.0 && reflection[1].2 > 1.0,
        "{reflection:?}"
    );
    // Wheel slip (odometry amplification): the large clamp pulls the estimate back, the small
    // one cannot keep up.
    assert_eq!(slip[0].1, 2, "{slip:?}");
    assert_eq!(slip[1].1, 0, "{slip:?}");
    assert!(slip[0].2 > 1.0 && slip[1].2 < 1.0, "{slip:?}");
}

#[test]
fn a_sweep_of_fault_values_is_a_grid_and_deterministic() {
    let case = fixture("placed-wheel-slip.json");
    let sets = ["fault[0].param=1.5,4", "fault[0].duration=100,300"];
    let first = sweep(&case, &sets);
    assert_eq!(first.points.len(), 4);
    assert_eq!(first.points[1].values, [1.5, 300.0]);
    // A weak, short slip passes; a strong, long one fails.
    assert_eq!(first.points[0].failed_runs(), 0);
    assert_eq!(first.points[3].failed_runs(), 2);
    let again = sweep(&case, &sets);
    assert_eq!(again, first);

    let bad = drivecheck(&["sweep", path(&case), "--set", "fault[3].param=1"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        text(&bad).contains("fault[0] to fault[0]"),
        "{}",
        text(&bad)
    );
}
