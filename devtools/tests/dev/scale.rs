//! `drivecheck-dev bench scale` on a small size.

use crate::common::{drivecheck, path, text};

/// `bench scale` runs every step as a process of its own and reads each one's peak memory: a
/// small size gives a row with every figure measured (Linux: `/proc/self/status`).
#[test]
fn bench_scale_measures_every_reader_of_a_campaign() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = dir.path().join("bench");
    let out = drivecheck(&[
        "bench",
        "scale",
        "--sizes",
        "6",
        "--jobs",
        "2",
        "--scratch",
        path(&scratch),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let row = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("6 "))
        .unwrap_or_else(|| panic!("no row for 6 tests: {}", text(&out)));
    if cfg!(target_os = "linux") {
        assert!(!row.contains('?'), "a peak memory was not measured: {row}");
    }
    // The steps' run directories are there: the campaign, its report, the merged shards.
    for step in [
        "6/run/campaign.json",
        "6/report.html",
        "6/merged/campaign.json",
    ] {
        assert!(
            scratch.join(step).is_file(),
            "{step} missing: {}",
            text(&out)
        );
    }
}
