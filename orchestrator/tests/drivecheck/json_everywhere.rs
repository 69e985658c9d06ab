//! `--json` on every command that prints a result: one JSON document on standard output that
//! `python3 -m json.tool` reads, in the envelope every command shares (`command`, then
//! `schema_version`, then the result: `orchestrator::output::json`), with the keys and versions
//! docs/json.md names. The test walks the command line's own definition, so a command that gains
//! `--json` without being tried here fails it, as does a command tried here that lost it.

use crate::common;

use std::collections::BTreeSet;
use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};

use common::{drivecheck, path, text};
use orchestrator::output::json;

/// The commands (as typed, `runs show`) whose definition has a `--json` option.
fn commands_with_json() -> BTreeSet<String> {
    fn walk(command: &clap::Command, name: &str, found: &mut BTreeSet<String>) {
        if command
            .get_arguments()
            .any(|a| a.get_long() == Some("json"))
        {
            found.insert(name.trim().to_owned());
        }
        for sub in command.get_subcommands() {
            walk(sub, &format!("{name} {}", sub.get_name()), found);
        }
    }
    let mut cli = orchestrator::cli::command();
    // Propagates the global options (`runs --json`) to the subcommands.
    cli.build();
    let mut found = BTreeSet::new();
    walk(&cli, "", &mut found);
    found
}

/// What python3's own JSON reader says of `stdout` (`None` when there is no python3 here).
fn python_reads(stdout: &[u8]) -> Option<Result<(), String>> {
    let mut child = Command::new("python3")
        .args(["-m", "json.tool"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .ok()?;
    child.stdin.take()?.write_all(stdout).ok()?;
    let out = child.wait_with_output().ok()?;
    Some(if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).into_owned())
    })
}

/// The documents and their schema versions as docs/json.md's table of them says: its rows
/// ``| `COMMAND` | VERSION | … |``.
fn documented_versions() -> BTreeSet<(String, u32)> {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/json.md"))
        .expect("docs/json.md");
    doc.lines()
        .filter_map(|line| {
            let mut cells = line.strip_prefix("| `")?.split(" | ");
            let command = cells.next()?.strip_suffix('`')?;
            let version = cells.next()?.trim().parse().ok()?;
            Some((command.to_owned(), version))
        })
        .collect()
}

/// Runs `drivecheck args`, expects one of `codes`, checks that standard output is one JSON
/// document (for serde and for python3) in the envelope of `document` (its first key `command`,
/// its second `schema_version`, as `orchestrator::output::json` says), and returns it.
fn json_of(document: &str, args: &[&str], codes: &[i32]) -> serde_json::Value {
    let out: Output = drivecheck(args);
    assert!(
        out.status.code().is_some_and(|c| codes.contains(&c)),
        "drivecheck {}: exit {:?}\n{}",
        args.join(" "),
        out.status.code(),
        text(&out)
    );
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "drivecheck {}: stdout is not one JSON document ({e})\n{}",
            args.join(" "),
            text(&out)
        )
    });
    if let Some(read) = python_reads(&out.stdout) {
        read.unwrap_or_else(|e| panic!("python3 -m json.tool refused it: {e}"));
    }
    let known = json::ALL
        .iter()
        .find(|d| d.command == document)
        .unwrap_or_else(|| panic!("{document}: not in orchestrator::output::json::ALL"));
    let envelope = format!(
        "{{\n  \"command\": \"{document}\",\n  \"schema_version\": {},\n",
        known.schema_version
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.starts_with(&envelope),
        "drivecheck {}: the document does not begin with the envelope {envelope:?}:\n{}",
        args.join(" "),
        &stdout[..stdout.len().min(400)]
    );
    value
}

/// `value` has every key of `keys`.
fn has_keys(value: &serde_json::Value, keys: &[&str], what: &str) {
    for key in keys {
        assert!(value.get(key).is_some(), "{what}: no `{key}` in {value:#}");
    }
}

/// The documents of the campaign commands (`run`, `runs merge`).
fn is_campaign_document(value: &serde_json::Value, command: &str, tests: usize) {
    assert_eq!(value["command"], command);
    has_keys(value, &["dir", "campaign", "tests"], command);
    assert_eq!(
        value["tests"].as_array().map(Vec::len),
        Some(tests),
        "{value:#}"
    );
    assert_eq!(value["campaign"]["format"], "drivecheck-campaign");
}

#[test]
fn every_command_that_prints_a_result_prints_one_json_document() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    // The commands tried (as clap names them) and the documents printed (`explain --score`).
    let mut tried = BTreeSet::new();
    let mut printed = BTreeSet::new();
    let mut try_it = |document: &str, args: &[&str], codes: &[i32]| {
        let command = document.split(" --").next().unwrap_or(document);
        tried.insert(command.to_owned());
        printed.insert(document.to_owned());
        json_of(document, args, codes)
    };

    let run_dir = d("runs/campaign");
    let run = try_it(
        "run",
        &[
            "run",
            "--seed",
            "7",
            "--tests",
            "3",
            "--out",
            path(&run_dir),
            "--json",
        ],
        &[0, 1],
    );
    is_campaign_document(&run, "run", 3);
    let case = run_dir.join("case-000.json");

    let listed = try_it("runs", &["runs", "--dir", path(&d("runs")), "--json"], &[0]);
    assert_eq!(listed["command"], "runs");
    let runs = listed["runs"].as_array().expect("runs is a list");
    assert_eq!(runs.len(), 1, "{listed:#}");
    assert_eq!(runs[0]["kind"], "campaign");

    let shown = try_it(
        "runs show",
        &["runs", "show", path(&run_dir), "--json"],
        &[0],
    );
    assert_eq!(shown["kind"], "campaign");
    has_keys(&shown, &["campaign", "tests", "recording"], "runs show");
    assert_eq!(shown["recording"]["complete"], true);

    for k in ["1/2", "2/2"] {
        let shard = d(&format!("shard{}", &k[..1]));
        let out = drivecheck(&[
            "run",
            "--seed",
            "7",
            "--tests",
            "3",
            "--shard",
            k,
            "--out",
            path(&shard),
        ]);
        assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    }
    let merged = try_it(
        "runs merge",
        &[
            "runs",
            "merge",
            path(&d("shard1")),
            path(&d("shard2")),
            "--out",
            path(&d("merged")),
            "--json",
        ],
        &[0],
    );
    is_campaign_document(&merged, "runs merge", 3);
    assert_eq!(
        merged["dir"],
        path(&d("merged")),
        "the merged directory, not its staging"
    );

    let replay = try_it(
        "replay",
        &[
            "replay",
            path(&case),
            "--times",
            "1",
            "--out",
            path(&d("replay")),
            "--json",
        ],
        &[0, 1],
    );
    assert_eq!(replay["command"], "replay");
    assert_eq!(replay["replay"]["format"], "drivecheck-replay");

    let shrink = try_it(
        "shrink",
        &[
            "shrink",
            path(&case),
            "--runs",
            "1",
            "--budget",
            "3s",
            "--out",
            path(&d("shrink")),
            "--json",
        ],
        &[0, 1],
    );
    assert_eq!(shrink["command"], "shrink");
    assert!(shrink["shrunk"].is_boolean(), "{shrink:#}");

    let sweep = try_it(
        "sweep",
        &[
            "sweep",
            path(&case),
            "--set",
            "sim.range_sigma_m=0.05,0.1",
            "--runs",
            "1",
            "--json",
        ],
        &[0],
    );
    assert_eq!(sweep["sweep"]["format"], "drivecheck-sweep", "{sweep:#}");

    let explained = try_it("explain", &["explain", path(&run_dir), "--json"], &[0]);
    has_keys(&explained, &["cases"], "explain");
    let scored = try_it(
        "explain --score",
        &[
            "explain",
            path(&run_dir),
            "--score",
            "--counterfactual-runs",
            "0",
            "--json",
        ],
        &[0],
    );
    has_keys(&scored, &["cases", "scored"], "explain --score");
    let fault_free_recorded = d("fault-free");
    let out = drivecheck(&[
        "-q",
        "run",
        "--seed",
        "7",
        "--tests",
        "2",
        "--no-faults",
        "--out",
        path(&fault_free_recorded),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let calibrated = try_it(
        "explain --calibrate",
        &[
            "explain",
            path(&fault_free_recorded),
            "--calibrate",
            "--json",
        ],
        &[0],
    );
    has_keys(&calibrated, &["samples", "segments"], "explain --calibrate");

    let twin = try_it(
        "twin check",
        &["twin", "check", path(&run_dir), "--runs", "1", "--json"],
        &[0],
    );
    assert_eq!(twin["twin"]["format"], "drivecheck-twin", "{twin:#}");
    assert_eq!(twin["file"], path(&run_dir.join("twin.json")));

    let area = try_it(
        "area validate",
        &[
            "area",
            "validate",
            "--scenario",
            "courtyard",
            "--km",
            "0.2",
            "--seed",
            "1",
            "--json",
        ],
        &[0, 1],
    );
    has_keys(&area, &["verdict", "km"], "area validate");

    let route = try_it(
        "route generate",
        &[
            "route",
            "generate",
            "courtyard",
            "--points",
            "8",
            "--seed",
            "1",
            "--json",
        ],
        &[0],
    );
    has_keys(&route, &["seed", "points"], "route generate");
    let back = try_it(
        "route return",
        &[
            "route",
            "return",
            "--scenario",
            "parking-lot-rock",
            "--from",
            "-21,-110,0",
            "--json",
        ],
        &[0, 1],
    );
    has_keys(&back, &["seed", "points", "length_m"], "route return");

    let compared = try_it(
        "compare",
        &["compare", path(&run_dir), path(&run_dir), "--json"],
        &[0],
    );
    assert_eq!(compared["command"], "compare");
    assert_eq!(compared["comparison"]["significance"], "no_difference");

    let list = try_it("scenario list", &["scenario", "list", "--json"], &[0]);
    assert_eq!(list["command"], "scenario list");
    let check = try_it(
        "scenario check",
        &["scenario", "check", "courtyard", "--json"],
        &[0],
    );
    assert_eq!(check["command"], "scenario check");

    let dry_run = try_it("run --dry-run", &["run", "--dry-run", "--json"], &[0]);
    has_keys(&dry_run, &["firmware", "round_trip_ms"], "run --dry-run");

    // The firmware built for the host needs a tree (docs/sitl.md): under CI=true there is one.
    match std::env::var_os("DRIVECHECK_FIRMWARE_10").filter(|v| !v.is_empty()) {
        Some(tree) => {
            let tree = std::path::PathBuf::from(tree);
            let built = try_it(
                "sitl build",
                &["sitl", "build", path(&tree), "--json"],
                &[0],
            );
            assert_eq!(built["command"], "sitl build");
        }
        None => {
            assert_ne!(
                std::env::var("CI").as_deref(),
                Ok("true"),
                "CI=true and no firmware tree for `sitl build --json`"
            );
            common::skipped("firmware", "sitl build --json (no firmware tree)");
            tried.insert("sitl build".to_owned());
        }
    }
    assert_eq!(
        tried,
        commands_with_json(),
        "the commands tried here and the commands with --json differ"
    );
    let every_document: BTreeSet<String> = json::ALL.iter().map(|d| d.command.to_owned()).collect();
    assert_eq!(printed, every_document, "a document was not printed here");
    let versions: BTreeSet<(String, u32)> = json::ALL
        .iter()
        .map(|d| (d.command.to_owned(), d.schema_version))
        .collect();
    assert_eq!(
        documented_versions(),
        versions,
        "docs/json.md's table of documents and their versions"
    );
}

#[test]
fn the_runs_directory_comes_from_the_environment() {
    let dir = tempfile::tempdir().unwrap();
    let runs = dir.path().join("elsewhere");
    let out = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["run", "--seed", "3", "--tests", "1", "--json"])
        .env("DRIVECHECK_RUNS_DIR", &runs)
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let result: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let run_dir = Path::new(result["dir"].as_str().unwrap());
    assert!(
        run_dir.starts_with(&runs),
        "{} not in {}",
        run_dir.display(),
        runs.display()
    );
    assert!(!dir.path().join("runs").exists(), "nothing in ./runs");
    let listed = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["runs", "--json"])
        .env("DRIVECHECK_RUNS_DIR", &runs)
        .current_dir(dir.path())
        .output()
        .unwrap();
    let listed: serde_json::Value = serde_json::from_slice(&listed.stdout).unwrap();
    assert_eq!(
        listed["runs"].as_array().map(Vec::len),
        Some(1),
        "{listed:#}"
    );
}

#[test]
fn completions_and_manual_pages_come_from_the_command_line() {
    for shell in ["bash", "zsh", "fish"] {
        let out = drivecheck(&["completions", shell]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        let script = String::from_utf8_lossy(&out.stdout);
        let options = if shell == "fish" {
            ["-l scenario", "-l json"]
        } else {
            ["--scenario", "--json"]
        };
        for word in ["replay", "dry-run"].into_iter().chain(options) {
            assert!(script.contains(word), "{shell}: no {word}");
        }
        // A scenario completes to the bundled names, and (bash, fish) to files as well.
        assert!(
            script.contains("parking-lot-2anchors"),
            "{shell}: no bundled names"
        );
        match shell {
            "bash" => assert!(script.contains("-- \"${cur}\") $(compgen -f -- \"${cur}\"))")),
            "fish" => assert!(script.contains("-r -F -a \"")),
            _ => {}
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let out = drivecheck(&["man", "--out", path(dir.path())]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let main = std::fs::read_to_string(dir.path().join("drivecheck.1")).unwrap();
    assert!(
        main.starts_with(".ie") || main.contains(".TH drivecheck"),
        "{main}"
    );
    let run = std::fs::read_to_string(dir.path().join("drivecheck-run.1")).unwrap();
    assert!(
        run.contains("stale\\-after"),
        "the run page names its options: {run}"
    );
    assert!(dir.path().join("drivecheck-runs-show.1").exists());
    // The exit statuses and the environment have sections of their own on the main page, and
    // no page names a page that is not written (there is no drivecheck-help).
    for section in [".SH \"EXIT STATUS\"", ".SH ENVIRONMENT"] {
        assert!(main.contains(section), "no {section}: {main}");
    }
    for variable in ["DRIVECHECK_RUNS_DIR", "DRIVECHECK_SITL_CACHE", "RUST_LOG"] {
        assert!(main.contains(variable), "no {variable}: {main}");
    }
    let written: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    for name in &written {
        let page = std::fs::read_to_string(dir.path().join(name)).unwrap();
        assert!(!page.contains(".SH EXTRA"), "{name}: {page}");
        // Every `drivecheck…(1)` a page names (roff writes `-` as `\-`).
        let page = page.replace("\\-", "-");
        for (at, _) in page.match_indices("(1)") {
            let start = page[..at]
                .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                .map_or(0, |k| k + 1);
            let named = &page[start..at];
            if named.starts_with("drivecheck") {
                let file = format!("{named}.1");
                assert!(written.contains(&file), "{name} names {file}, not written");
            }
        }
    }
}
