//! `-q` on every command: standard error stays empty when the command succeeds (its result on
//! standard output, its files written), and errors still print. The test walks the command line's
//! own definition (`orchestrator::cli::command()`, as `json_everywhere` does for `--json`), so a
//! command added without being run here with `-q` fails it. Every command runs here on the
//! embedded simulated car and bundled inputs (scenarios, the repository's fixtures); `sim`
//! serves until a signal stops it. The one exception to `-q` by design, a safety warning (a car
//! left with fault injection enabled, `runner/src/session_end.rs`), needs a car that stops
//! answering as its session ends: the runner's `session_end` tests see it reported, and
//! `orchestrator::output`'s that such a line prints with `-q`.
//!
//! And `-v` is what prints the bundled scenarios' drawing warnings (about data the user cannot
//! change), not the default.

use crate::common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{drivecheck, path, text};

/// The commands that do something (as typed: `runs show`): every command of the definition but
/// clap's `help` and the groups that only hold subcommands.
fn commands() -> BTreeSet<String> {
    fn walk(command: &clap::Command, path: &str, found: &mut BTreeSet<String>) {
        for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
            let path = format!("{path} {}", sub.get_name()).trim_start().to_owned();
            if !sub.is_subcommand_required_set() {
                found.insert(path.clone());
            }
            walk(sub, &path, found);
        }
    }
    let mut root = orchestrator::cli::command();
    root.build();
    let mut found = BTreeSet::new();
    walk(&root, "", &mut found);
    found
}

/// The workspace's root, where the fixtures are named from.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the orchestrator crate is in the workspace")
        .to_owned()
}

/// What is run: every command with `-q`, the commands named as the definition names them.
struct Quiet {
    tried: BTreeSet<String>,
    runs: usize,
}

impl Quiet {
    /// Runs `drivecheck args` with `-q` (before the command one time, after its arguments the
    /// next), expects an exit status of `codes` and nothing on standard error; `command` is the
    /// command as the definition names it.
    fn run(&mut self, command: &str, args: &[&str], codes: &[i32]) -> Output {
        self.tried.insert(command.to_owned());
        self.runs += 1;
        let mut all: Vec<&str> = Vec::with_capacity(args.len() + 1);
        if self.runs.is_multiple_of(2) {
            all.push("-q");
            all.extend_from_slice(args);
        } else {
            all.extend_from_slice(args);
            all.push("-q");
        }
        let out = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
            .args(&all)
            .current_dir(root())
            .output()
            .expect("the drivecheck binary runs");
        assert!(
            out.status.code().is_some_and(|c| codes.contains(&c)),
            "drivecheck {}: exit {:?}\n{}",
            all.join(" "),
            out.status.code(),
            text(&out)
        );
        assert!(
            out.stderr.is_empty(),
            "drivecheck {}: -q, yet on standard error:\n{}",
            all.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
        out
    }
}

/// The first failing case of the campaign in `dir` (its `campaign.json`'s summary).
fn failing_case(dir: &Path) -> PathBuf {
    let summary = common::summary(dir);
    let file = summary["failing_cases"][0]
        .as_str()
        .unwrap_or_else(|| panic!("the campaign has a failing case: {summary:#}"));
    dir.join(file)
}

/// `drivecheck -q sim …` until SIGINT: the car serves (its address file written) and says
/// nothing.
fn quiet_sim(dir: &Path) {
    let address_file = dir.join("sim.addr");
    let mut sim = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args([
            "-q",
            "sim",
            "--scenario",
            "parking-lot-2anchors",
            "--listen",
        ])
        .arg("127.0.0.1:0")
        .arg("--address-file")
        .arg(&address_file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while std::fs::read_to_string(&address_file)
        .unwrap_or_default()
        .trim()
        .is_empty()
    {
        if started.elapsed() > Duration::from_secs(20) {
            let _ = (sim.kill(), sim.wait());
            panic!("the simulated car did not write its address within 20 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let killed = Command::new("kill")
        .args(["-INT", &sim.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let out = sim.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        out.stderr.is_empty(),
        "sim -q, yet on standard error:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn every_command_with_quiet_prints_nothing_on_standard_error_but_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let d = |name: &str| tmp.path().join(name);
    let mut q = Quiet {
        tried: BTreeSet::new(),
        runs: 0,
    };

    // A campaign with everything that says where it wrote: JUnit, the report, the shrinks.
    let campaign = d("runs/campaign");
    let junit = d("campaign.xml");
    q.run(
        "run",
        &[
            "run",
            "--seed",
            "11",
            "--tests",
            "6",
            "--out",
            path(&campaign),
            "--junit",
            path(&junit),
            "--report",
            "--shrink",
            "--shrink-budget",
            "1s",
        ],
        &[1],
    );
    assert!(junit.is_file() && campaign.join("report.html").is_file());
    q.run("run", &["run", "--dry-run"], &[0]);
    q.run(
        "run",
        &["run", "--tests", "2", "--json", "--out", path(&d("j"))],
        &[0, 1],
    );
    let case = failing_case(&campaign);
    let case = path(&case);

    q.run(
        "replay",
        &[
            "replay",
            case,
            "--out",
            path(&d("replay")),
            "--junit",
            path(&d("replay.xml")),
            "--report",
        ],
        &[0, 1],
    );
    q.run(
        "replay",
        &[
            "replay",
            case,
            "--vary-seed",
            "--times",
            "2",
            "--out",
            path(&d("vary")),
        ],
        &[0, 1],
    );
    q.run(
        "shrink",
        &[
            "shrink",
            case,
            "--runs",
            "1",
            "--budget",
            "1s",
            "--out",
            path(&d("shrink")),
        ],
        &[0],
    );
    q.run(
        "sweep",
        &[
            "sweep",
            case,
            "--set",
            "sim.range_sigma_m=0.05,0.1",
            "--runs",
            "1",
        ],
        &[0],
    );

    q.run("runs", &["runs", "--dir", path(&d("runs"))], &[0]);
    q.run(
        "runs show",
        &["runs", "show", path(&campaign), "--coverage"],
        &[0],
    );
    for k in ["1/2", "2/2"] {
        let shard = d(&format!("shard{}", &k[..1]));
        q.run(
            "run",
            &[
                "run",
                "--seed",
                "7",
                "--tests",
                "3",
                "--shard",
                k,
                "--out",
                path(&shard),
            ],
            &[0, 1],
        );
    }
    let shards = [d("shard1"), d("shard2")];
    for (out, json) in [("merged", false), ("merged-json", true)] {
        let mut args = vec!["runs", "merge", path(&shards[0]), path(&shards[1]), "--out"];
        let out = d(out);
        let junit = out.with_extension("xml");
        args.extend([path(&out), "--junit", path(&junit)]);
        if json {
            args.push("--json");
        }
        q.run("runs merge", &args, &[0]);
    }

    q.run(
        "report",
        &[
            "report",
            path(&campaign),
            "--out",
            path(&d("report.html")),
            "--scenario",
            "parking-lot-2anchors",
        ],
        &[0],
    );
    q.run("explain", &["explain", path(&campaign)], &[0]);
    q.run(
        "explain",
        &[
            "explain",
            path(&campaign),
            "--score",
            "--counterfactual-runs",
            "1",
        ],
        &[0],
    );
    q.run(
        "compare",
        &[
            "compare",
            path(&campaign),
            path(&campaign),
            &format!("--report={}", path(&d("compare.html"))),
        ],
        &[0],
    );
    q.tried.insert("sim".to_owned());
    quiet_sim(tmp.path());
    q.run(
        "calibrate",
        &[
            "calibrate",
            path(&campaign),
            "--out",
            path(&d("fitted.toml")),
            "--max-evaluations",
            "2",
            "--restarts",
            "0",
        ],
        &[0],
    );
    q.run(
        "twin check",
        &["twin", "check", path(&campaign), "--runs", "1"],
        &[0],
    );

    // The scenario commands: no seed given (the seed line is a note), pictures and files
    // written, a scenario file with warnings, a GeoJSON file's coordinates.
    let warned = "tests/fixtures/warnings/recovery-far-from-start.toml";
    q.run(
        "area validate",
        &[
            "area",
            "validate",
            "courtyard",
            "--km",
            "0.2",
            "-o",
            path(&d("area.svg")),
        ],
        &[0, 1],
    );
    q.run(
        "area validate",
        &["area", "validate", warned, "--km", "0.2"],
        &[0, 1],
    );
    q.run(
        "route generate",
        &["route", "generate", "courtyard", "--points", "8"],
        &[0],
    );
    q.run(
        "route generate",
        &["route", "generate", warned, "--points", "8"],
        &[0],
    );
    q.run(
        "route return",
        &[
            "route",
            "return",
            "parking-lot-rock",
            "--from",
            "-21,-110,0",
        ],
        &[0],
    );
    q.run(
        "scenario import",
        &[
            "scenario",
            "import",
            "tests/fixtures/xml/courtyard.xml",
            "-o",
            path(&d("c.toml")),
        ],
        &[0],
    );
    q.run(
        "scenario import",
        &[
            "scenario",
            "import",
            "tests/fixtures/geojson/qgis-lot.geojson",
        ],
        &[0],
    );
    q.run("scenario import", &["scenario", "import", warned], &[0]);
    q.run(
        "scenario export",
        &[
            "scenario",
            "export",
            "courtyard",
            "--origin",
            "61.45,23.85",
            "-o",
            path(&d("c.geojson")),
        ],
        &[0],
    );
    q.run("scenario check", &["scenario", "check", "courtyard"], &[0]);
    q.run("scenario check", &["scenario", "check", warned], &[0]);
    q.run("scenario list", &["scenario", "list"], &[0]);
    q.run("completions", &["completions", "bash"], &[0]);
    q.run("man", &["man", "--out", path(&d("man"))], &[0]);
    q.run("man", &["man"], &[0]);
    // The firmware built for the host needs a tree (docs/sitl.md): under CI=true there is one.
    match std::env::var_os("DRIVECHECK_FIRMWARE_10").filter(|v| !v.is_empty()) {
        Some(tree) => {
            let tree = PathBuf::from(tree);
            q.run("sitl build", &["sitl", "build", path(&tree)], &[0]);
        }
        None => {
            assert_ne!(std::env::var("CI").as_deref(), Ok("true"));
            q.tried.insert("sitl build".to_owned());
        }
    }

    assert_eq!(
        q.tried,
        commands(),
        "the commands run here with -q and the commands of the definition differ"
    );

    // Errors still print.
    let refused = drivecheck(&["-q", "scenario", "check", "no-such-area"]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(
        String::from_utf8_lossy(&refused.stderr).starts_with("error: "),
        "{}",
        text(&refused)
    );
}

#[test]
fn a_bundled_scenarios_drawing_warnings_are_for_verbose() {
    for args in [
        &["scenario", "check", "courtyard"][..],
        &[
            "area",
            "validate",
            "courtyard",
            "--km",
            "0.2",
            "--seed",
            "1",
        ],
        &[
            "route",
            "generate",
            "courtyard",
            "--points",
            "8",
            "--seed",
            "1",
        ],
    ] {
        let default = drivecheck(args);
        let default_err = String::from_utf8_lossy(&default.stderr);
        assert!(
            !default_err.contains("warning:"),
            "{args:?}: a bundled scenario's warnings without -v: {default_err}"
        );
        let verbose = drivecheck(&[&["-v"], args].concat());
        assert_eq!(default.status.code(), verbose.status.code());
        let verbose_err = String::from_utf8_lossy(&verbose.stderr);
        assert!(
            verbose_err.contains("warning: "),
            "{args:?}: -v prints them: {}",
            text(&verbose)
        );
    }
    let check = drivecheck(&["scenario", "check", "courtyard"]);
    assert!(
        String::from_utf8_lossy(&check.stdout).contains("(a bundled scenario's: -v prints them)"),
        "{}",
        text(&check)
    );
    // A file's warnings are for everyone (but -q).
    let file = root().join("tests/fixtures/warnings/recovery-far-from-start.toml");
    let check = drivecheck(&["scenario", "check", path(&file)]);
    assert!(
        String::from_utf8_lossy(&check.stderr).contains("warning: "),
        "{}",
        text(&check)
    );
}

#[test]
fn each_commands_help_says_what_quiet_and_verbose_do_for_it() {
    let help = |args: &[&str]| {
        let out = drivecheck(args);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let area = help(&["area", "validate", "--help"]);
    assert!(area.contains("no seed line"), "{area}");
    assert!(!area.contains("a campaign's summary"), "{area}");
    let run = help(&["run", "--help"]);
    assert!(run.contains("A safety warning"), "{run}");
    let completions = help(&["completions", "--help"]);
    assert!(
        !completions.contains("--quiet") && !completions.contains("--verbose"),
        "nothing for -q or -v to do: not offered\n{completions}"
    );
    let top = help(&["--help"]);
    assert!(
        top.contains("--quiet") && top.contains("safety warning"),
        "{top}"
    );
}
