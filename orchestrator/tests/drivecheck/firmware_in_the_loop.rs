//! `--car sitl:TREE`: the car's own firmware built for the host and driven in virtual time, a
//! fresh start of it per test (`docs/sitl.md#in-a-campaign`).
//!
//! The trees come from the environment as for the `sitl` crate's tests (`DRIVECHECK_FIRMWARE_10`,
//! `DRIVECHECK_FIRMWARE_12`); without them each test says `skipped: no firmware tree` and passes,
//! except under `CI=true`, where it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use super::common::{cases, path, skipped, text};

/// The trees given, with the firmware profile of their generation for the simulated car.
pub(super) fn trees() -> Vec<(&'static str, PathBuf)> {
    let found: Vec<_> = [
        ("DRIVECHECK_FIRMWARE_10", "10.1"),
        ("DRIVECHECK_FIRMWARE_12", "12.3"),
    ]
    .into_iter()
    .filter_map(|(var, version)| {
        std::env::var_os(var)
            .filter(|v| !v.is_empty())
            .map(|p| (version, PathBuf::from(p)))
    })
    .collect();
    if found.is_empty() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true and no firmware tree: set DRIVECHECK_FIRMWARE_10 / DRIVECHECK_FIRMWARE_12"
        );
        skipped(
            "firmware",
            "no firmware tree (DRIVECHECK_FIRMWARE_10, DRIVECHECK_FIRMWARE_12)",
        );
    }
    found
}

/// `drivecheck ARGS` with the build cache in the test's target folder.
fn drivecheck(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(args)
        .env(
            "DRIVECHECK_SITL_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("sitl-cache"),
        )
        .output()
        .expect("the drivecheck binary runs")
}

/// `run -q --seed 1 --tests N ARGS --record none --out OUT`, exit 0 or 1.
fn campaign(out: &Path, tests: usize, args: &[&str]) {
    let tests = tests.to_string();
    let mut all = vec!["-q", "run", "--seed", "1", "--tests", &tests];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--record", "none", "--out", path(out)]);
    let output = drivecheck(&all);
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "{}",
        text(&output)
    );
}

/// Each case's verdict.
fn verdicts(dir: &Path) -> Vec<String> {
    cases(dir)
        .values()
        .map(|text| {
            let case: serde_json::Value = serde_json::from_str(text).unwrap();
            case["verdict"].to_string()
        })
        .collect()
}

#[test]
fn a_campaign_on_the_firmware_is_deterministic_and_agrees_with_the_simulated_car() {
    for (version, tree) in trees() {
        let dir = tempfile::tempdir().unwrap();
        let car = format!("sitl:{}", tree.display());
        let (a, b, sim) = (
            dir.path().join("a"),
            dir.path().join("b"),
            dir.path().join("sim"),
        );
        campaign(&a, 10, &["--car", &car, "--jobs", "2"]);
        campaign(&b, 10, &["--car", &car, "--jobs", "1"]);
        // the same firmware, seed and plant give the same cases, whatever the jobs
        super::common::assert_same_campaign(&a, &b);
        let (va, summary) = (verdicts(&a), super::common::summary(&a));
        assert_eq!(va.len(), 10, "{version}: {summary}");
        assert_eq!(summary["aborted"], 0, "{version}: {summary}");
        // the simulated car of that generation, the same seed: its model of the firmware
        let profile = dir.path().join("profile.toml");
        std::fs::write(
            &profile,
            format!("format = \"drivecheck-car-profile\"\nversion = 1\nfirmware = \"{version}\"\n"),
        )
        .unwrap();
        campaign(&sim, 10, &["--car", "sim", "--profile", path(&profile)]);
        let agreed = va
            .iter()
            .zip(verdicts(&sim))
            .filter(|(x, y)| **x == *y)
            .count();
        assert!(
            agreed >= 8,
            "{version}: the firmware and the simulated car agree on {agreed} of 10 verdicts"
        );
    }
}

#[test]
fn the_dry_run_passes_on_the_firmware() {
    for (version, tree) in trees() {
        let car = format!("sitl:{}", tree.display());
        let out = drivecheck(&["run", "--dry-run", "--car", &car]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(stdout.contains("dry run passed"), "{stdout}");
        assert!(stdout.contains(&format!("firmware {version}")), "{stdout}");
    }
}

#[test]
fn a_folder_that_is_not_a_firmware_tree_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let car = format!("sitl:{}", dir.path().display());
    let out = drivecheck(&["run", "--tests", "1", "--car", &car]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&dir.path().display().to_string()) && stderr.contains("firmware"),
        "{stderr}"
    );
}

/// `replay`, `sweep`, `shrink` and `twin check` take `--car sitl:TREE` as `run` does: every run
/// a fresh start of the firmware driving the simulated car's physical car. A case of a campaign
/// on the firmware, replayed on it, is its own test again to the last digit; a setting of the
/// embedded simulator's model of the firmware is refused on the firmware itself.
#[test]
fn replay_sweep_shrink_and_twin_check_drive_the_firmware() {
    for (version, tree) in trees() {
        let dir = tempfile::tempdir().unwrap();
        let car = format!("sitl:{}", tree.display());
        let run = dir.path().join("run");
        campaign(&run, 3, &["--car", &car]);
        let case = run.join("case-001.json");

        let replayed = dir.path().join("replay");
        let out = drivecheck(&[
            "replay",
            path(&case),
            "--car",
            &car,
            "--out",
            path(&replayed),
        ]);
        assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
        let replay: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(replayed.join("replay.json")).unwrap())
                .unwrap();
        assert_eq!(
            replay["reproduction"]["identical"], true,
            "{version}: {replay:#}"
        );

        let out = drivecheck(&[
            "sweep",
            path(&case),
            "--car",
            &car,
            "--runs",
            "1",
            "--seed",
            "1",
            "--set",
            "sim.range_sigma_m=0.02,0.2",
            "--json",
        ]);
        assert_eq!(out.status.code(), Some(0), "{version}: {}", text(&out));
        let sweep: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(
            sweep["sweep"]["points"].as_array().unwrap().len(),
            2,
            "{sweep:#}"
        );
        let refused = drivecheck(&[
            "sweep",
            path(&case),
            "--car",
            &car,
            "--set",
            "sim.uwb_clamp_m=0.1",
        ]);
        assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
        assert!(
            text(&refused).contains("the car's own firmware built for the host has its own"),
            "{}",
            text(&refused)
        );

        let shrunk = dir.path().join("shrink");
        let out = drivecheck(&[
            "shrink",
            path(&case),
            "--car",
            &car,
            "--runs",
            "1",
            // Enough for a few candidates on the firmware (7 tried in 2 s on 12.3): what is checked
            // is that shrink drives it, not how small the case gets.
            "--budget",
            "2s",
            "--out",
            path(&shrunk),
        ]);
        assert!(
            matches!(out.status.code(), Some(0 | 1)),
            "{version}: {}",
            text(&out)
        );

        let out = drivecheck(&[
            "twin",
            "check",
            path(&run),
            "--car",
            &car,
            "--runs",
            "1",
            "--json",
        ]);
        assert_eq!(out.status.code(), Some(0), "{version}: {}", text(&out));
        let twin = String::from_utf8_lossy(&out.stdout);
        assert!(twin.contains("verdicts_agreed"), "{twin}");
    }
}

/// `calibrate --car sitl:TREE` fits the physical car around the car's own firmware: a campaign
/// driven on the firmware in a car whose anchor 50 stands 0.4 m east of its surveyed place
/// (recorded without the profile), calibrated on the firmware from the default profile, puts the
/// anchor back within the fit's 0.1 m tolerance. One tree (the first given): the fit drives 24
/// candidates of 6 tests each.
#[test]
fn calibrate_on_the_firmware_finds_a_displaced_anchor() {
    let Some((_, tree)) = trees().into_iter().next() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let car = format!("sitl:{}", tree.display());
    let held = dir.path().join("held.toml");
    std::fs::write(
        &held,
        "format = \"drivecheck-car-profile\"\nversion = 1\n\n[anchors.\"50\"]\noffset_m = [0.4, 0.0]\n",
    )
    .unwrap();
    let run = dir.path().join("run");
    let out = drivecheck(&[
        "-q",
        "run",
        "--seed",
        "7",
        "--tests",
        "6",
        "--car",
        &car,
        "--profile",
        path(&held),
        "--record",
        "all",
        "--out",
        path(&run),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let fitted = dir.path().join("fitted.toml");
    let out = drivecheck(&[
        "calibrate",
        path(&run),
        "--car",
        &car,
        "--max-evaluations",
        "24",
        "--restarts",
        "0",
        "--out",
        path(&fitted),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let profile = std::fs::read_to_string(&fitted).unwrap();
    assert!(
        profile.contains(" on the firmware ") && profile.contains(" built for the host (tree "),
        "{profile}"
    );
    let east: f64 = profile
        .split("[anchors.\"50\"]\noffset_m = [")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .unwrap_or_else(|| panic!("no offset of anchor 50: {profile}"))
        .trim()
        .parse()
        .unwrap();
    assert!(
        (east - 0.4).abs() <= 0.1,
        "anchor 50 east {east}: {profile}"
    );
    // The recorded error is explained far better than from the start.
    let said = String::from_utf8_lossy(&out.stdout);
    let misfit = |after: &str| -> f64 {
        let rest = &said[said.find(after).unwrap_or_else(|| panic!("{said}")) + after.len()..];
        rest.split(" m").next().unwrap().trim().parse().unwrap()
    };
    let (fit, start) = (misfit("rms misfit "), misfit("(start "));
    assert!(fit < start / 2.0, "{said}");
}

/// A tree whose `conf_general.c` gives the car another wheel drives a simulated car with that
/// wheel: the geometry comes from the configuration the firmware boots with (GET_MAIN_CONFIG), and
/// the command says where it differs from the generation's defaults. One tree (the first given).
#[test]
fn a_tree_with_another_wheel_drives_a_car_with_that_wheel() {
    let Some((_, tree)) = trees().into_iter().next() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("tree");
    sitl::variant::copy_tree(&tree, &copy).unwrap();
    let conf = copy.join("conf_general.c");
    let source = std::fs::read_to_string(&conf).unwrap();
    let default = "conf->car.wheel_diam = 0.11;";
    assert!(source.contains(default), "{}: no {default}", conf.display());
    std::fs::write(
        &conf,
        source.replacen(default, "conf->car.wheel_diam = 0.13;", 1),
    )
    .unwrap();
    let car = format!("sitl:{}", copy.display());
    let out = drivecheck(&["run", "--dry-run", "--car", &car]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        text(&out).contains("another geometry than ")
            && text(&out).contains("defaults: wheel_diam 0.13 (0.11)"),
        "{}",
        text(&out)
    );
    // The tree as given boots with its generation's defaults: nothing to say.
    let out = drivecheck(&[
        "run",
        "--dry-run",
        "--car",
        &format!("sitl:{}", tree.display()),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(!text(&out).contains("another geometry"), "{}", text(&out));
}

/// `drivecheck sitl build TREE` says what it built: the version, the tree's hash, the files
/// compiled and the symbols the shim stubs; the second build comes from the cache.
#[test]
fn sitl_build_says_what_went_into_the_executable() {
    for (version, tree) in trees() {
        let first = drivecheck(&["sitl", "build", path(&tree), "--json"]);
        assert_eq!(first.status.code(), Some(0), "{}", text(&first));
        let built: serde_json::Value = serde_json::from_slice(&first.stdout).unwrap();
        assert_eq!(built["command"], "sitl build", "{built:#}");
        assert_eq!(built["firmware"], version, "{built:#}");
        assert_eq!(built["tree_hash"].as_str().unwrap().len(), 64, "{built:#}");
        let compiled: Vec<&str> = built["compiled"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f.as_str().unwrap())
            .collect();
        assert!(
            compiled.iter().any(|f| f.ends_with("pos_uwb.c")),
            "{compiled:?}"
        );
        assert!(
            !built["stubbed"].as_array().unwrap().is_empty(),
            "{built:#}"
        );
        assert!(Path::new(built["executable"].as_str().unwrap()).is_file());
        let again = drivecheck(&["sitl", "build", path(&tree)]);
        let said = String::from_utf8_lossy(&again.stdout);
        assert!(said.contains("from the cache"), "{said}");
    }
    let not_a_tree = tempfile::tempdir().unwrap();
    let out = drivecheck(&["sitl", "build", path(not_a_tree.path())]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("not a firmware tree"), "{}", text(&out));
}

/// A campaign on the firmware names the tree it drove (`campaign.json`'s
/// `car_firmware_tree_hash`, the hash `sitl build` prints), and its resume refuses the tree once
/// it changed: the tests after it would be another firmware's.
#[test]
fn a_campaign_names_its_firmware_tree_and_its_resume_refuses_a_changed_one() {
    let Some((_, tree)) = trees().into_iter().next() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("RC_Controller");
    let copied = Command::new("cp")
        .arg("-r")
        .arg(&tree)
        .arg(&copy)
        .status()
        .unwrap();
    assert!(copied.success());
    let car = format!("sitl:{}", copy.display());
    let run = dir.path().join("run");
    campaign(&run, 3, &["--car", &car]);
    let built = drivecheck(&["sitl", "build", path(&copy), "--json"]);
    let built: serde_json::Value = serde_json::from_slice(&built.stdout).unwrap();
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("campaign.json")).unwrap()).unwrap();
    assert_eq!(
        record["car_firmware_tree_hash"], built["tree_hash"],
        "{record:#}"
    );

    // The user changes the firmware; the cut-off campaign is not resumed on it.
    std::fs::remove_file(run.join("case-002.json")).unwrap();
    let first_compiled = built["compiled"][0].as_str().expect("a compiled source");
    let source = copy.join(first_compiled);
    let mut changed = std::fs::read_to_string(&source).unwrap();
    changed.push_str("\n/* changed */\n");
    std::fs::write(&source, changed).unwrap();
    let out = drivecheck(&[
        "run",
        "--resume",
        path(&run),
        "--car",
        &car,
        "--record",
        "none",
    ]);
    let said = text(&out);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(said.contains("now hashes to"), "{said}");
    assert!(!run.join("case-002.json").exists(), "{said}");
}

/// The degradation the gate test and `bench compare --car sitl:TREE` make of a tree of each
/// generation (`docs/sitl.md#a-firmware-regression-gate`): (file, constant, new number).
fn degradation(version: &str) -> (&'static str, &'static str, &'static str) {
    if version.starts_with("10.") {
        // the UWB antenna's offset along the car entered with the wrong sign
        ("pos_uwb.c", "OFFSET_X", "-0.085")
    } else {
        // the UWB correction gate tightened from 0.1 to 0.02 m (beyond it a range moves the
        // estimate by a full 0.2 m step)
        ("conf_general.c", "uwb_max_corr", "0.02")
    }
}

/// `compare BASE NEW --fail-on regression`: its exit status and what it said.
fn gate(base: &Path, new: &Path) -> (Option<i32>, String) {
    let out = drivecheck(&["compare", path(base), path(new), "--fail-on", "regression"]);
    (out.status.code(), text(&out))
}

/// The firmware regression gate of `docs/sitl.md`, small: the BASE tree's run, the candidate's
/// run of the same cases (`--cases-from`, the BASE run's seed), `compare --fail-on regression`.
/// The same tree as candidate gives the same case files and the gate passes (exit 0); a copy of
/// the tree with one constant degraded fails it (exit 1). With 10 tests each degradation moves
/// a segment's largest deviation by about +0.06–0.08 m (median; `bench compare --car sitl:TREE`
/// measures how often 10 tests find it, on both trees). On the newest tree given only: each tree
/// costs three campaigns and a build of the degraded copy.
#[test]
fn the_regression_gate_passes_the_same_firmware_and_fails_a_degraded_one() {
    if let Some((version, tree)) = trees().into_iter().last() {
        let dir = tempfile::tempdir().unwrap();
        let car = format!("sitl:{}", tree.display());
        let base = dir.path().join("base");
        campaign(&base, 10, &["--car", &car]);
        let candidate = |car: &str, out: &Path| {
            let output = drivecheck(&[
                "-q",
                "run",
                "--car",
                car,
                "--cases-from",
                path(&base),
                "--record",
                "none",
                "--out",
                path(out),
            ]);
            assert!(
                matches!(output.status.code(), Some(0 | 1)),
                "{version}: {}",
                text(&output)
            );
        };
        let same = dir.path().join("same");
        candidate(&car, &same);
        super::common::assert_same_campaign(&base, &same);
        let (code, said) = gate(&base, &same);
        assert_eq!(code, Some(0), "{version}: the same firmware: {said}");

        let degraded_tree = dir.path().join("degraded-tree");
        sitl::variant::copy_tree(&tree, &degraded_tree).unwrap();
        let (file, constant, value) = degradation(version);
        sitl::variant::set_constant(&degraded_tree, file, constant, value).unwrap();
        let degraded = dir.path().join("degraded");
        candidate(&format!("sitl:{}", degraded_tree.display()), &degraded);
        let (code, said) = gate(&base, &degraded);
        assert_eq!(
            code,
            Some(1),
            "{version}: {constant} = {value} in {file}: {said}"
        );
        assert!(said.contains("significantly worse"), "{version}: {said}");
        // the tree itself is left as it was
        let original = std::fs::read_to_string(tree.join(file)).unwrap();
        assert_ne!(
            original,
            std::fs::read_to_string(degraded_tree.join(file)).unwrap()
        );
    }
}
