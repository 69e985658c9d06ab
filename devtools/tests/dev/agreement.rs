//! `drivecheck-dev bench agreement` on a small run: the firmware trees from
//! `DRIVECHECK_FIRMWARE_10` / `DRIVECHECK_FIRMWARE_12` (without them the test says `skipped: no
//! firmware tree`, and fails under `CI=true`).

use crate::common::{drivecheck, path, text};

#[test]
fn bench_agreement_pairs_the_firmware_and_the_model_test_by_test() {
    let trees: Vec<String> = ["DRIVECHECK_FIRMWARE_10", "DRIVECHECK_FIRMWARE_12"]
        .into_iter()
        .filter_map(|var| std::env::var(var).ok().filter(|v| !v.is_empty()))
        .collect();
    if trees.is_empty() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true and no firmware tree: set DRIVECHECK_FIRMWARE_10 / DRIVECHECK_FIRMWARE_12"
        );
        println!("skipped: no firmware tree");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scratch = dir.path().join("bench");
    let mut args = vec!["bench", "agreement", "--seeds", "1", "--tests", "3"];
    for tree in &trees {
        args.extend(["--tree", tree.as_str()]);
    }
    args.extend(["--scratch", path(&scratch)]);
    let output = drivecheck(&args);
    assert_eq!(output.status.code(), Some(0), "{}", text(&output));
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(said.contains("| tree | verdicts agreed |"), "{said}");
    // one row per tree, each of 3 tests paired
    assert_eq!(said.matches(" / 3 |").count(), trees.len(), "{said}");
    // the simulated car drove the firmware's version
    let record: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            scratch
                .join("tree-0-seed-1")
                .join("model")
                .join("campaign.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let firmware: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            scratch
                .join("tree-0-seed-1")
                .join("firmware")
                .join("campaign.json"),
        )
        .unwrap(),
    )
    .unwrap();
    assert_eq!(
        record["car_firmware_version"],
        firmware["car_firmware_version"]
    );
}
