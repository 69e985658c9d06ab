//! What the end-to-end tests of the `drivecheck` binary share: running it and showing its output.

#![allow(dead_code)] // each test file uses its own part

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use recording::Recording;

/// Runs the `drivecheck` binary with `args` and waits for it.
pub fn drivecheck(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(args)
        .output()
        .expect("the drivecheck binary runs")
}

/// The run's standard output and error, for an assertion's message.
pub fn text(output: &Output) -> String {
    format!(
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// Says that a test skipped a part of itself, and why, where the user sees it: straight to the
/// process's standard error, which the test harness does not capture (a skip that only
/// `--nocapture` shows reads as a pass). When `DRIVECHECK_REQUIRE` (a comma-separated list,
/// which `.ci/run` sets for what it installed) names `what`, the skip is a failure instead.
pub fn skipped(what: &str, why: &str) {
    let required = std::env::var("DRIVECHECK_REQUIRE").unwrap_or_default();
    assert!(
        !required.split(',').any(|r| r.trim() == what),
        "{what} is required (DRIVECHECK_REQUIRE={required}) but {why}"
    );
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "skipped ({what}): {why}");
}

/// A temporary path as a command-line argument.
pub fn path(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

/// `drivecheck -q run ARGS --record none --out OUT`; its exit status must be 0 or 1.
pub fn run_unrecorded(args: &[&str], out: &Path) {
    let mut all = vec!["-q", "run"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--record", "none", "--out", path(out)]);
    let output = drivecheck(&all);
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "{}",
        text(&output)
    );
}

/// `PATH` with the directory of the `drivecheck` under test first.
pub fn path_with_drivecheck() -> String {
    let bin = Path::new(env!("CARGO_BIN_EXE_drivecheck"))
        .parent()
        .unwrap();
    format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    )
}

/// Four tests of seed 1 without faults in the rock lot of a scenario file
/// (`fixtures/rock-wide-shadow.toml`, a rock hiding anchor 234; not a bundled scenario), every
/// segment judged (`--on-failure continue`); some fail (exit status 1). Its run directory.
pub fn rock_campaign(dir: &Path) -> PathBuf {
    campaign(
        dir,
        1,
        4,
        &[
            "--scenario",
            concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/tests/fixtures/rock-wide-shadow.toml"
            ),
            "--no-faults",
            "--on-failure",
            "continue",
        ],
        1,
    )
}

/// Runs a campaign (`drivecheck run --seed SEED --tests TESTS [extra] --out DIR/campaign`),
/// expects exit status `code`, and returns the run directory.
pub fn campaign(dir: &Path, seed: u64, tests: usize, extra: &[&str], code: i32) -> PathBuf {
    let out_dir = dir.join("campaign");
    let (seed, tests) = (seed.to_string(), tests.to_string());
    let mut args = vec!["run", "--seed", &seed, "--tests", &tests];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", path(&out_dir)]);
    let out = drivecheck(&args);
    assert_eq!(out.status.code(), Some(code), "{}", text(&out));
    out_dir
}

/// The case files of a run directory, by name.
pub fn cases(dir: &Path) -> BTreeMap<String, String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with("case-") && name.ends_with(".json"))
        .map(|name| {
            let text = std::fs::read_to_string(dir.join(&name)).unwrap();
            (name, text)
        })
        .collect()
}

/// `campaign.json`'s summary.
pub fn summary(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("campaign.json")).unwrap();
    let record: serde_json::Value = serde_json::from_str(&text).unwrap();
    record["summary"].clone()
}

/// Every message of a recording: topic, log time and bytes, in file order.
pub fn messages(dir: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let recording = Recording::read(&dir.join("campaign.mcap")).unwrap();
    assert!(recording.is_complete());
    recording
        .held()
        .into_iter()
        .map(|m| (m.topic().name().to_owned(), m.log_time(), m.data().to_vec()))
        .collect()
}

/// Asserts two recordings hold the same messages, naming the first difference.
pub fn assert_same_messages(a: &Path, b: &Path) {
    let (ma, mb) = (messages(a), messages(b));
    let first = ma.iter().zip(&mb).position(|(x, y)| x != y);
    let show = |m: Option<&(String, u64, Vec<u8>)>| {
        m.map(|(topic, t, data)| format!("{topic} at {t}: {}", String::from_utf8_lossy(data)))
    };
    assert!(
        first.is_none() && ma.len() == mb.len(),
        "{} has {} messages, {} has {}; first difference at {first:?}: {:?} and {:?}",
        a.display(),
        ma.len(),
        b.display(),
        mb.len(),
        show(first.and_then(|i| ma.get(i))),
        show(first.and_then(|i| mb.get(i)))
    );
}

/// Asserts two run directories hold the same case files, byte for byte, and the same summary.
pub fn assert_same_campaign(a: &Path, b: &Path) {
    let (ca, cb) = (cases(a), cases(b));
    assert!(!ca.is_empty());
    assert_eq!(ca.keys().collect::<Vec<_>>(), cb.keys().collect::<Vec<_>>());
    for (name, text) in &ca {
        assert!(
            cb[name] == *text,
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
    assert_eq!(summary(a), summary(b));
}

/// The shell block after `<!-- scaling-test: NAME -->` in `docs/scaling.md`.
pub fn documented(name: &str) -> String {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/scaling.md"))
        .unwrap();
    let marker = format!("<!-- scaling-test: {name} -->");
    let after = &doc[doc.find(&marker).unwrap_or_else(|| panic!("{marker}")) + marker.len()..];
    let block = after.split("```sh\n").nth(1).unwrap();
    block.split("\n```").next().unwrap().trim().to_owned()
}

/// A `drivecheck sim` car listening on a free loopback port (its address file in `dir`, named
/// after `name`), and its address (`tcp://127.0.0.1:PORT`). Kill the child when done.
pub fn start_sim(dir: &Path, name: &str) -> (std::process::Child, String) {
    start_sim_with(dir, name, "parking-lot-2anchors", &[], 10)
}

/// The bundled `parking-lot-2anchors` with short tests, written into `dir`: its geometry, anchors
/// and faults, but one or two commands a test at 10–12 km/h, and the hand-drawn start and recovery
/// routes driven at 9 km/h instead of 3. For the wall-clock tests of what a campaign does around
/// its tests (a car lost, a resume), which pay every second a test drives: a test and its reset
/// take about 12 s instead of about 28 s.
pub fn short_tests(dir: &Path) -> PathBuf {
    let bundled = scenarios::bundled::text("parking-lot-2anchors").unwrap();
    let mut short = String::new();
    for line in bundled.lines() {
        let line = match line {
            l if l.starts_with("test_size = ") => "test_size = { min = 1, max = 2 }".to_owned(),
            l if l.starts_with("speed_kmh = ") => {
                "speed_kmh = { min = 10.0, max = 12.0 }".to_owned()
            }
            l => l.replace("speed = 0.833333", "speed = 2.5"),
        };
        short.push_str(&line);
        short.push('\n');
    }
    assert!(
        short.contains("test_size = { min = 1,")
            && short.contains("speed_kmh = { min = 10.0,")
            && short.contains("speed = 2.5")
            && !short.contains("speed = 0.833333"),
        "the bundled scenario's lines changed: {short}"
    );
    let file = dir.join("short-tests.toml");
    std::fs::write(&file, short).unwrap();
    file
}

/// [`start_sim`] on `scenario` (a bundled name or a file) with `extra` arguments (`--car
/// sitl:TREE`), waiting up to `within_s` seconds for its address.
pub fn start_sim_with(
    dir: &Path,
    name: &str,
    scenario: &str,
    extra: &[&str],
    within_s: u64,
) -> (std::process::Child, String) {
    let address_file = dir.join(format!("{name}.addr"));
    let mut sim = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["sim", "--scenario", scenario, "--listen"])
        .arg("127.0.0.1:0")
        .arg("--address-file")
        .arg(&address_file)
        .args(extra)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    for _ in 0..within_s * 20 {
        let car = std::fs::read_to_string(&address_file).unwrap_or_default();
        if !car.trim().is_empty() {
            let car = car.trim().to_owned();
            assert!(car.starts_with("tcp://"), "{car:?}");
            return (sim, car);
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = (sim.kill(), sim.wait());
    panic!("the simulated car {name} did not say its address within {within_s} s");
}

/// The port of the live view a campaign says it serves, from its line `live view:
/// ws://127.0.0.1:PORT …` on standard error (a campaign given `--live 127.0.0.1:0`).
pub fn live_port(line: &str) -> Option<u16> {
    line.strip_prefix("live view: ws://127.0.0.1:")
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|port| port.parse().ok())
}
