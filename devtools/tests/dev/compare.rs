//! `drivecheck-dev bench compare` on a small run.

use serde_json::Value;

use crate::common::{drivecheck, path, text};

#[test]
fn bench_compare_measures_false_alarms_noise_and_power_on_a_small_run() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = dir.path().join("bench");
    let output = drivecheck(&[
        "bench",
        "compare",
        "--tests",
        "8",
        "--pairs",
        "1",
        "--scratch",
        path(&scratch),
    ]);
    assert_eq!(output.status.code(), Some(0), "{}", text(&output));
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(said.contains("noise (same car, other seed)"), "{said}");
    assert!(said.contains("| the default car, other seed |"), "{said}");
    assert!(said.contains("| anchor 50 biased 0.5 m |"), "{said}");
    assert!(
        said.contains("firmware 10.1 (BASE) against firmware 12.3"),
        "{said}"
    );
    // Every run drove the same cases.
    let record: Value = serde_json::from_str(
        &std::fs::read_to_string(scratch.join("firmware-12").join("campaign.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(record["cases_from"]["tests"], 8);
    assert_eq!(record["car_firmware_version"], "12.3");
}
