//! Tidy: the layering ARCHITECTURE.md states, checked on the source as text (in the manner of
//! rust-analyzer's tidy tests). Each rule names what it forbids and where; a rule that fails
//! lists every offending line. The last test checks that every invariant ARCHITECTURE.md states
//! in bold names a test that checks it, and that those tests exist.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The workspace root (this crate lives in `tests/`).
fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate is inside the workspace")
        .to_path_buf()
}

/// Every `.rs` file under `dir` (relative to the workspace), skipping build output.
fn rust_files(dir: &str) -> Vec<(String, String)> {
    fn walk(root: &Path, dir: &Path, found: &mut Vec<(String, String)>) {
        let Ok(entries) = fs::read_dir(dir) else {
            return;
        };
        let mut entries: Vec<PathBuf> = entries.map(|e| e.expect("an entry").path()).collect();
        entries.sort();
        for path in entries {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if name != "target" && !name.starts_with('.') && name != "fuzz" {
                    walk(root, &path, found);
                }
            } else if name.ends_with(".rs") {
                let relative = path
                    .strip_prefix(root)
                    .expect("under the root")
                    .to_string_lossy()
                    .into_owned();
                let text = fs::read_to_string(&path).expect("a source file");
                found.push((relative, text));
            }
        }
    }
    let root = workspace();
    let mut found = Vec::new();
    walk(&root, &root.join(dir), &mut found);
    found
}

/// Whether `file` holds only tests (a `tests.rs`, a `*_tests.rs`, an integration test).
fn is_test_file(file: &str) -> bool {
    let name = file.rsplit('/').next().unwrap_or(file);
    name == "tests.rs"
        || name == "proptests.rs"
        || name == "fuzz.rs"
        || name.ends_with("_tests.rs")
        || file.contains("/tests/")
}

/// The code lines of `text` with their numbers: comments and every `#[cfg(test)]` item (a test
/// module, a test-only `use` or function) left out — only the item, so that code after a test
/// module is still read (by its braces: the item ends where they balance, or at its `;`).
fn code_lines(text: &str) -> Vec<(usize, &str)> {
    let mut lines = Vec::new();
    let (mut in_test_item, mut depth) = (false, 0i64);
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim();
        if !in_test_item && trimmed == "#[cfg(test)]" {
            (in_test_item, depth) = (true, 0);
            continue;
        }
        if in_test_item {
            let opens = line.matches('{').count() as i64;
            let closes = line.matches('}').count() as i64;
            depth += opens - closes;
            let attribute = trimmed.starts_with("#[");
            if !attribute && depth <= 0 && (closes > 0 || trimmed.ends_with(';')) {
                in_test_item = false;
            }
            continue;
        }
        if !trimmed.starts_with("//") {
            lines.push((i + 1, line));
        }
    }
    lines
}

/// The lines of the files under `dirs` (test files left out unless `tests`) on which `forbidden`
/// says what is wrong, as `file:line: what`.
fn offences(
    dirs: &[&str],
    tests: bool,
    forbidden: impl Fn(&str, &str) -> Option<String>,
) -> Vec<String> {
    let mut found = Vec::new();
    for dir in dirs {
        for (file, text) in rust_files(dir) {
            if !tests && is_test_file(&file) {
                continue;
            }
            for (number, line) in code_lines(&text) {
                if let Some(what) = forbidden(&file, line) {
                    found.push(format!("{file}:{number}: {what}: {}", line.trim()));
                }
            }
        }
    }
    found
}

fn assert_none(rule: &str, found: Vec<String>) {
    assert!(found.is_empty(), "{rule}:\n{}", found.join("\n"));
}

/// The first of `words` that `line` holds as a word (not inside a longer identifier).
fn holds_word<'a>(line: &str, words: &[&'a str]) -> Option<&'a str> {
    words.iter().copied().find(|word| {
        line.match_indices(word).any(|(at, _)| {
            let before = line[..at].chars().next_back();
            let after = line[at + word.len()..].chars().next();
            let ident = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
            !ident(before) && !ident(after)
        })
    })
}

// ---------------------------------------------------------------------------------------------
// The crates' layers

/// Our crates' packages and the packages of ours each may use as a normal dependency: a crate
/// uses only crates of lower layers (ARCHITECTURE.md, *Layers*).
const LAYERS: &[(&str, &[&str])] = &[
    ("trajgen", &[]),
    ("recovery", &["trajgen"]),
    ("car-link", &[]),
    ("scenarios", &["trajgen", "car-link"]),
    (
        "campaign",
        &["trajgen", "recovery", "scenarios", "car-link"],
    ),
    ("car-sim", &["car-link", "scenarios"]),
    // builds the car's own firmware for the host and runs it as a process of its own
    ("sitl", &[]),
    (
        "recording",
        &["trajgen", "scenarios", "car-link", "car-sim", "campaign"],
    ),
    (
        "runner",
        &[
            "trajgen",
            "recovery",
            "scenarios",
            "car-link",
            "car-sim",
            "sitl",
            "campaign",
            "recording",
        ],
    ),
    (
        "report",
        &[
            "trajgen",
            "scenarios",
            "car-link",
            "car-sim",
            "campaign",
            "recording",
            "runner",
        ],
    ),
    (
        "drivecheck",
        &[
            "trajgen",
            "recovery",
            "scenarios",
            "car-link",
            "car-sim",
            "sitl",
            "campaign",
            "recording",
            "runner",
            "report",
        ],
    ),
    (
        "drivecheck-dev",
        &[
            "trajgen",
            "recovery",
            "scenarios",
            "car-link",
            "car-sim",
            "campaign",
            "sitl",
            "recording",
            "runner",
            "report",
            "drivecheck",
        ],
    ),
    ("drivecheck-tests", &[]),
    // Benchmarks only: what they measure is among their dev-dependencies.
    ("drivecheck-benches", &[]),
];

/// Every workspace member's package name and the packages of ours among its normal
/// dependencies (a workspace dependency named `orchestrator` is the package `drivecheck`).
fn our_dependencies() -> BTreeMap<String, BTreeSet<String>> {
    let root = workspace();
    let manifest: toml::Table = fs::read_to_string(root.join("Cargo.toml"))
        .expect("the workspace manifest")
        .parse()
        .expect("TOML");
    let workspace = manifest["workspace"].as_table().expect("[workspace]");
    // workspace dependency key -> package
    let mut ours = BTreeMap::new();
    for (key, value) in workspace["dependencies"].as_table().expect("dependencies") {
        if let Some(path) = value.get("path").and_then(|p| p.as_str()) {
            let package = value
                .get("package")
                .and_then(|p| p.as_str())
                .map_or_else(|| key.clone(), str::to_owned);
            ours.insert(key.clone(), (package, path.to_owned()));
        }
    }
    let mut result = BTreeMap::new();
    for member in workspace["members"].as_array().expect("members") {
        let member = member.as_str().expect("a member path");
        let text = fs::read_to_string(root.join(member).join("Cargo.toml")).expect("a manifest");
        let manifest: toml::Table = text.parse().expect("TOML");
        let name = manifest["package"]["name"]
            .as_str()
            .expect("a name")
            .to_owned();
        let deps = manifest
            .get("dependencies")
            .and_then(|d| d.as_table())
            .map(|deps| {
                deps.keys()
                    .filter_map(|key| ours.get(key).map(|(package, _)| package.clone()))
                    .collect()
            })
            .unwrap_or_default();
        result.insert(name, deps);
    }
    result
}

/// Every crate of ours uses only the crates of ours its layer allows, and every member has a
/// layer (a new crate is given its place in ARCHITECTURE.md and here).
#[test]
fn each_crate_uses_only_lower_layers() {
    let layers: BTreeMap<&str, BTreeSet<&str>> = LAYERS
        .iter()
        .map(|(name, deps)| (*name, deps.iter().copied().collect()))
        .collect();
    let mut problems = Vec::new();
    for (package, deps) in our_dependencies() {
        let Some(allowed) = layers.get(package.as_str()) else {
            problems.push(format!(
                "{package}: no layer (add it to LAYERS and ARCHITECTURE.md)"
            ));
            continue;
        };
        for dep in deps {
            if !allowed.contains(dep.as_str()) {
                problems.push(format!(
                    "{package} uses {dep}, which its layer does not allow"
                ));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The report reads files and formats them: it never calls a command (the `drivecheck` crate),
/// in its manifest or its source.
#[test]
fn the_report_calls_no_command() {
    let deps = our_dependencies();
    assert!(
        !deps["report"].contains("drivecheck"),
        "report depends on drivecheck"
    );
    assert_none(
        "the report names the command line's crate",
        offences(&["report/src"], true, |_, line| {
            holds_word(line, &["orchestrator", "commands"])
                .filter(|_| line.contains("::"))
                .map(|w| format!("names `{w}`"))
        }),
    );
}

/// The vehicle seam sits below the runner it serves: `runner/src/vehicle/` uses nothing of the
/// runner (no `crate::` path but `crate::vehicle`, no `super::super`).
#[test]
fn the_vehicle_seam_uses_nothing_of_the_runner() {
    assert_none(
        "the seam uses the runner",
        offences(&["runner/src/vehicle"], true, |_, line| {
            let above = line
                .match_indices("crate::")
                .any(|(at, _)| !line[at..].starts_with("crate::vehicle"));
            (above || line.contains("super::super")).then(|| "a path above the seam".to_owned())
        }),
    );
}

/// The pure crates have no I/O, clock, async runtime or threads: `campaign`, `trajgen`,
/// `recovery`, and `car-link`'s protocol (every module but `client`, `health`, `transport`,
/// which its `client` feature adds). Their manifests have no runtime among normal dependencies.
#[test]
fn the_pure_crates_have_no_io_clock_runtime_or_threads() {
    const FORBIDDEN: &[&str] = &[
        "tokio",
        "std::fs",
        "std::net",
        "std::thread",
        "std::process",
        "std::env",
        "Instant",
        "SystemTime",
        "indicatif",
        "File",
    ];
    let mut found = offences(
        &["campaign/src", "trajgen/src", "recovery/src"],
        true,
        |_, line| holds_word(line, FORBIDDEN).map(|w| format!("`{w}`")),
    );
    found.extend(offences(&["car-link/src"], false, |file, line| {
        let client = ["client", "health", "transport"]
            .iter()
            .any(|m| file.starts_with(&format!("car-link/src/{m}")))
            || file == "car-link/src/lib.rs";
        (!client)
            .then(|| holds_word(line, FORBIDDEN))
            .flatten()
            .map(|w| format!("`{w}`"))
    }));
    assert_none("I/O, a clock, a runtime or threads in a pure crate", found);
    let root = workspace();
    for krate in ["campaign", "trajgen", "recovery"] {
        let manifest: toml::Table = fs::read_to_string(root.join(krate).join("Cargo.toml"))
            .expect("a manifest")
            .parse()
            .expect("TOML");
        let deps = manifest.get("dependencies").and_then(|d| d.as_table());
        for runtime in ["tokio", "indicatif", "tempfile", "futures"] {
            assert!(
                deps.is_none_or(|d| !d.contains_key(runtime)),
                "{krate} depends on {runtime}"
            );
        }
    }
}

/// The runner, the commands, the report and the development tools drive a car only through the
/// seam: `car_link::Car` is named in `runner/src/vehicle/` alone.
#[test]
fn only_the_seam_names_a_concrete_car() {
    assert_none(
        "a concrete car outside the seam",
        offences(
            &[
                "runner/src",
                "report/src",
                "orchestrator/src",
                "devtools/src",
            ],
            true,
            |file, line| {
                if file.starts_with("runner/src/vehicle/") {
                    return None;
                }
                (line.contains("car_link::Car") && holds_word(line, &["Car"]).is_some()
                    || line.contains("Car::"))
                .then(|| "names `car_link::Car`".to_owned())
            },
        ),
    );
}

/// What a command prints on standard error goes through `orchestrator::output`, which decides what
/// `-q` and `-v` print: no other `eprintln!` (the error `process::main` prints, and the campaign's
/// progress lines `commands/progress.rs` prints as `output` says, excepted) and no progress bar
/// but `output::bar`'s (and the campaign's, hidden with `-q`).
#[test]
fn standard_error_is_written_through_output() {
    let found = offences(&["orchestrator/src"], false, |file, line| {
        let anywhere = [
            "orchestrator/src/output.rs",
            "orchestrator/src/commands/progress.rs",
        ];
        if anywhere.contains(&file) {
            return None;
        }
        if (line.contains("eprintln!") || line.contains("eprint!"))
            && !(file == "orchestrator/src/process.rs" && line.contains("eprintln!(\"error: "))
        {
            return Some("writes on standard error past `output`".to_owned());
        }
        (line.contains("ProgressBar::new")).then(|| "a progress bar past `output::bar`".to_owned())
    });
    assert_none("standard error written past orchestrator::output", found);
}

/// No code but the firmware model compares version numbers.
#[test]
fn only_the_firmware_model_compares_versions() {
    let comparison = |line: &str| {
        ["major", "minor"].iter().any(|field| {
            line.match_indices(field).any(|(at, _)| {
                let rest = line[at + field.len()..].trim_start();
                ["==", "!=", ">=", "<=", "> ", "< "]
                    .iter()
                    .any(|op| rest.starts_with(op))
                    && rest[2..]
                        .trim_start()
                        .starts_with(|c: char| c.is_ascii_digit())
            })
        }) || line.contains("is_12x")
    };
    let found = offences(
        &[
            "campaign/src",
            "car-sim/src",
            "car-link/src",
            "scenarios/src",
            "recording/src",
            "runner/src",
            "report/src",
            "orchestrator/src",
            "devtools/src",
        ],
        false,
        |file, line| {
            (!file.starts_with("car-link/src/firmware/") && comparison(line))
                .then(|| "compares a version number".to_owned())
        },
    );
    assert_none("a version comparison outside the firmware model", found);
}

/// No code matches on a fault kind or compares one to learn what it does: that is the kind's row
/// in `car_link::firmware::KINDS` (tests may name kinds as they like).
#[test]
fn only_the_kinds_table_matches_on_a_fault_kind() {
    const KINDS: [&str; 5] = ["Offset", "Amplification", "SetTo", "Bitflip", "None"];
    let matches = |line: &str| {
        line.match_indices("FaultKind::").any(|(at, _)| {
            let rest = &line[at + "FaultKind::".len()..];
            let Some(kind) = KINDS.iter().find(|k| rest.starts_with(*k)) else {
                return false;
            };
            let after = rest[kind.len()..].trim_start();
            let before = line[..at].trim_end();
            after.starts_with("=>")
                || after.starts_with('|')
                || after.starts_with("==")
                || after.starts_with("!=")
                || before.ends_with("==")
                || before.ends_with("!=")
                || before.ends_with('|')
        })
    };
    let found = offences(
        &[
            "campaign/src",
            "car-sim/src",
            "car-link/src",
            "scenarios/src",
            "trajgen/src",
            "recording/src",
            "runner/src",
            "report/src",
            "orchestrator/src",
            "devtools/src",
        ],
        false,
        |file, line| {
            (file != "car-link/src/firmware/fault_kinds.rs" && matches(line))
                .then(|| "matches on a fault kind".to_owned())
        },
    );
    assert_none("a fault-kind match outside KINDS", found);
}

/// Exit statuses are `orchestrator::exit::Exit`: nothing else ends the process with a number.
#[test]
fn only_exit_ends_the_process() {
    assert_none(
        "the process ended outside orchestrator::exit",
        offences(&["."], false, |file, line| {
            (line.contains("process::exit(") && file != "orchestrator/src/exit.rs")
                .then(|| "std::process::exit".to_owned())
        }),
    );
}

/// Nothing reads `../shared`: no source, manifest or build script of the workspace names it.
#[test]
fn nothing_reads_the_shared_folder() {
    assert_none(
        "a path into ../shared",
        offences(&["."], true, |file, line| {
            (file != "tests/tests/end_to_end/tidy.rs"
                && (line.contains("../shared") || line.contains("shared/firmware")))
            .then(|| "names ../shared".to_owned())
        }),
    );
}

/// tokio's pausable clock (`test-util`) is a normal dependency only of the crates that run the
/// embedded simulated car in virtual time (`runner`'s fresh cars, the command line's runtime).
#[test]
fn the_pausable_clock_is_where_virtual_time_runs() {
    let root = workspace();
    let mut with = Vec::new();
    for (member, _) in rust_files(".")
        .iter()
        .filter(|(file, _)| file.ends_with("/src/lib.rs") || file.ends_with("/src/main.rs"))
        .map(|(file, _)| (file.split('/').next().unwrap_or("").to_owned(), ()))
        .collect::<BTreeMap<_, _>>()
    {
        let Ok(text) = fs::read_to_string(root.join(&member).join("Cargo.toml")) else {
            continue;
        };
        let manifest: toml::Table = text.parse().expect("TOML");
        let tokio = manifest
            .get("dependencies")
            .and_then(|d| d.get("tokio"))
            .and_then(|t| t.get("features"))
            .and_then(|f| f.as_array());
        if tokio.is_some_and(|f| f.iter().any(|f| f.as_str() == Some("test-util"))) {
            with.push(member);
        }
    }
    assert_eq!(with, ["orchestrator", "runner"]);
}

/// Every random stream derives from the campaign seed: no code but the seed map
/// (`campaign/src/seed.rs`), the simulated car's noise streams (`car-sim/src/noise.rs`, seeded
/// from it) and the seed a command draws when none is given (`orchestrator/src/seed.rs`) seeds or
/// draws a generator.
#[test]
fn only_the_seed_map_makes_random_streams() {
    const MAKERS: &[&str] = &[
        "seed_from_u64",
        "from_entropy",
        "thread_rng",
        "rand::random",
        "rand::rng()",
        "OsRng",
        "from_seed(",
    ];
    const HOMES: &[&str] = &[
        "campaign/src/seed.rs",
        "car-sim/src/noise.rs",
        "orchestrator/src/seed.rs",
        // proptest's own ChaCha runner, seeded with the seed map's plan seed
        "campaign/src/model/mod.rs",
    ];
    let found = offences(
        &[
            "trajgen/src",
            "recovery/src",
            "scenarios/src",
            "car-link/src",
            "car-sim/src",
            "campaign/src",
            "recording/src",
            "runner/src",
            "report/src",
            "orchestrator/src",
            "devtools/src",
        ],
        false,
        |file, line| {
            (!HOMES.contains(&file))
                .then(|| MAKERS.iter().find(|m| line.contains(**m)))
                .flatten()
                .map(|m| format!("makes a random stream (`{m}`)"))
        },
    );
    assert_none("a random stream outside the seed map", found);
}

/// The simulated car never reads the wall clock: its time is tokio's (`tokio::time::Instant`),
/// never `std::time::Instant` or `SystemTime`.
#[test]
fn the_simulated_car_reads_no_wall_clock() {
    assert_none(
        "the wall clock in the simulated car",
        offences(&["car-sim/src"], false, |_, line| {
            let std_instant = line.contains("std::time::Instant")
                || (line.contains("std::time::{") && holds_word(line, &["Instant"]).is_some());
            (std_instant || line.contains("SystemTime")).then(|| "reads the wall clock".to_owned())
        }),
    );
}

/// Library crates return typed errors: no library crate has `anyhow` among its normal
/// dependencies (the command line and the development tools wrap the typed errors with context).
#[test]
fn library_crates_return_typed_errors() {
    let root = workspace();
    for krate in [
        "trajgen",
        "recovery",
        "scenarios",
        "car-link",
        "car-sim",
        "campaign",
        "recording",
        "runner",
        "report",
    ] {
        let manifest: toml::Table = fs::read_to_string(root.join(krate).join("Cargo.toml"))
            .expect("a manifest")
            .parse()
            .expect("TOML");
        let deps = manifest.get("dependencies").and_then(|d| d.as_table());
        assert!(
            deps.is_none_or(|d| !d.contains_key("anyhow")),
            "{krate} depends on anyhow: a library returns thiserror enums"
        );
        assert!(
            deps.is_some_and(|d| d.contains_key("thiserror")) || krate == "report",
            "{krate} has no thiserror"
        );
    }
}

/// campaign's top-level modules have no dependency cycle, and `files` (the file formats) uses
/// none of the modules that compute from cases.
#[test]
fn campaigns_top_level_modules_have_no_cycle() {
    let mut uses: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (file, text) in rust_files("campaign/src") {
        if is_test_file(&file) || file == "campaign/src/lib.rs" {
            continue;
        }
        let rest = &file["campaign/src/".len()..];
        let top = rest.split(['/', '.']).next().unwrap_or(rest).to_owned();
        let at_top = !rest.contains('/');
        let used = uses.entry(top.clone()).or_default();
        for (_, line) in code_lines(&text) {
            for prefix in ["crate::", "super::"] {
                if prefix == "super::" && !at_top {
                    continue;
                }
                for (at, _) in line.match_indices(prefix) {
                    let name: String = line[at + prefix.len()..]
                        .chars()
                        .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')
                        .collect();
                    if !name.is_empty() && name != top {
                        used.insert(name);
                    }
                }
            }
        }
    }
    for computed in ["drive", "coverage", "explain", "replay", "shrink", "sweep"] {
        assert!(
            !uses["files"].contains(computed),
            "campaign::files uses campaign::{computed}"
        );
    }
    // Depth-first search for a cycle.
    fn visit(
        node: &str,
        uses: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(start) = path.iter().position(|n| n == node) {
            let mut cycle = path[start..].to_vec();
            cycle.push(node.to_owned());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_owned());
        for next in uses.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(next, uses, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(node.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    assert!(uses.len() >= 10, "too few modules found: {:?}", uses.keys());
    for node in uses.keys() {
        if let Some(cycle) = visit(node, &uses, &mut Vec::new(), &mut done) {
            panic!("campaign's modules form a cycle: {}", cycle.join(" → "));
        }
    }
}

/// The workspace's members, as the root manifest lists them (folders relative to the root).
fn members() -> Vec<String> {
    let manifest: toml::Table = fs::read_to_string(workspace().join("Cargo.toml"))
        .expect("the workspace manifest")
        .parse()
        .expect("TOML");
    manifest["workspace"]["members"]
        .as_array()
        .expect("members")
        .iter()
        .map(|m| m.as_str().expect("a member").to_owned())
        .collect()
}

/// One integration-test binary per crate: a crate's `tests/` holds one `.rs` file or one folder
/// with a `main.rs` (its modules beside it), never several binaries each linking the whole graph.
#[test]
fn one_integration_test_binary_per_crate() {
    let root = workspace();
    let mut problems = Vec::new();
    for member in members() {
        let member = member.as_str();
        let Ok(entries) = fs::read_dir(root.join(member).join("tests")) else {
            continue;
        };
        let binaries: Vec<String> = entries
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "rs") || p.join("main.rs").is_file())
            .map(|p| p.display().to_string())
            .collect();
        if binaries.len() > 1 {
            problems.push(format!(
                "{member}: {} test binaries: {binaries:?}",
                binaries.len()
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// A target that `cargo test` leaves out holds nothing it would have run: a library or binary
/// with `test = false` has no `#[test]`, and a library with `doctest = false` no Rust example in
/// its documentation (a code block without a non-Rust language: `text`, `sh`, `toml`, …). The
/// build skips those targets to save compiling them again in test mode (the cold build of
/// `.ci/run`); a test added to one would otherwise never run.
#[test]
fn targets_left_out_of_cargo_test_have_nothing_to_run() {
    let root = workspace();
    let mut problems = Vec::new();
    for member in members() {
        let member = member.as_str();
        let crate_manifest: toml::Table = fs::read_to_string(root.join(member).join("Cargo.toml"))
            .expect("a member's manifest")
            .parse()
            .expect("TOML");
        let lib = crate_manifest.get("lib").and_then(|l| l.as_table());
        let lib_path = lib
            .and_then(|l| l.get("path"))
            .and_then(|p| p.as_str())
            .unwrap_or("src/lib.rs");
        let off = |table: Option<&toml::Table>, key: &str| {
            table.and_then(|t| t.get(key)).and_then(|v| v.as_bool()) == Some(false)
        };
        let mut targets: Vec<(String, bool, bool)> = Vec::new();
        if root.join(member).join(lib_path).is_file() {
            targets.push((lib_path.to_owned(), off(lib, "test"), off(lib, "doctest")));
        }
        for bin in crate_manifest
            .get("bin")
            .and_then(|b| b.as_array())
            .into_iter()
            .flatten()
        {
            let bin = bin.as_table();
            let path = bin
                .and_then(|b| b.get("path"))
                .and_then(|p| p.as_str())
                .unwrap_or("src/main.rs");
            targets.push((path.to_owned(), off(bin, "test"), false));
        }
        for (path, no_test, no_doctest) in targets {
            if !no_test && !no_doctest {
                continue;
            }
            // The target's own files: its root and the modules under its folder — for a binary
            // beside the library in one folder, its root alone.
            let root_file = Path::new(member).join(&path);
            let dir = root_file.parent().expect("a target file is in a folder");
            let beside_lib =
                path != lib_path && Path::new(&path).parent() == Path::new(lib_path).parent();
            let files = rust_files(&dir.to_string_lossy())
                .into_iter()
                .filter(|(file, _)| !beside_lib || Path::new(file) == root_file);
            for (file, text) in files {
                let mut in_block = false;
                for (number, line) in text.lines().enumerate() {
                    let line = line.trim_start();
                    if no_test && line.starts_with("#[test]") {
                        problems.push(format!(
                            "{file}:{}: a #[test] in {member}'s {path}, which has test = false",
                            number + 1
                        ));
                    }
                    let Some(lang) = line
                        .strip_prefix("///")
                        .or_else(|| line.strip_prefix("//!"))
                        .map(str::trim_start)
                        .and_then(|doc| doc.strip_prefix("```"))
                    else {
                        continue;
                    };
                    // A fence opens a block or closes the open one; an opening fence with no
                    // language, or a Rust one, is a doctest.
                    in_block = !in_block;
                    let rust = lang.trim().is_empty()
                        || lang.split(',').any(|l| {
                            matches!(
                                l.trim(),
                                "rust" | "no_run" | "should_panic" | "compile_fail" | "edition2024"
                            )
                        });
                    if no_doctest && in_block && rust {
                        problems.push(format!(
                            "{file}:{}: a Rust example in {member}'s documentation, which has \
                             doctest = false (give the block a language such as `text`, or let \
                             the doctests run)",
                            number + 1
                        ));
                    }
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The `drivecheck` binary's crate stays a shell over the engine: at most 8,000 lines of Rust
/// in `orchestrator/src` (counted as `tokei` counts code: neither comments nor blank lines),
/// tests beside the code included.
#[test]
fn the_binarys_crate_is_at_most_8000_lines() {
    let lines: usize = rust_files("orchestrator/src")
        .iter()
        .map(|(_, text)| {
            text.lines()
                .map(str::trim)
                .filter(|l| !l.is_empty() && !l.starts_with("//"))
                .count()
        })
        .sum();
    assert!(
        lines <= 8_000,
        "orchestrator/src holds {lines} lines of Rust, more than 8,000: move what the command \
         computes into the engine crate that owns it (ARCHITECTURE.md, the recipe for a command)"
    );
}

// ---------------------------------------------------------------------------------------------
// Every bold invariant is checked

/// Each invariant ARCHITECTURE.md states in bold (its sections *Invariants*, *Code map* and
/// *Files and their versions*), by the words it begins with, and the tests that check it (a
/// function name; its file is found by the search below).
const CHECKED_BY: &[(&str, &[&str])] = &[
    (
        "The pure crates have no I/O",
        &[
            "the_pure_crates_have_no_io_clock_runtime_or_threads",
            "the_same_seed_gives_the_same_trajectory",
            "plans_are_deterministic_drivable_and_within_the_slots",
        ],
    ),
    (
        "Every firmware fact has one home",
        &[
            "only_the_firmware_model_compares_versions",
            "layouts_follow_the_version",
        ],
    ),
    (
        "every fault kind, one row each",
        &[
            "every_kind_has_one_row",
            "only_the_kinds_table_matches_on_a_fault_kind",
        ],
    ),
    (
        "Every random stream derives from the campaign seed",
        &[
            "only_the_seed_map_makes_random_streams",
            "the_derived_seeds_are_the_ones_campaigns_were_recorded_with",
            "tests_and_campaigns_get_streams_of_their_own",
        ],
    ),
    (
        "A generation failure is an explicit error",
        &[
            "an_area_too_small_to_drive_in_is_a_typed_failure_never_a_short_extension",
            "from_a_random_pose_the_result_is_valid_or_a_typed_failure",
            "a_route_facing_the_fence_up_close_is_a_generation_error",
        ],
    ),
    (
        "Every segment a plan or replay sends has a verified ahead margin",
        &[
            "plans_are_deterministic_drivable_and_within_the_slots",
            "a_hand_written_case_gets_a_proven_ahead_margin_for_every_segment",
        ],
    ),
    (
        "A lost link is an error or an event",
        &[
            "a_lost_link_is_an_error_never_a_zero_state",
            "a_lost_link_ends_the_drive_at_once",
            "killing_the_simulator_mid_test_aborts_the_test_and_the_campaign",
        ],
    ),
    (
        "The runner never sends the next segment",
        &[
            "the_next_segment_waits_for_the_previous_one_to_be_confirmed",
            "a_campaign_runs_through_a_tapped_vehicle_as_the_runner_promises",
        ],
    ),
    (
        "always ends a test with the safe stop or braking",
        &[
            "the_safe_stop_rolls_out_the_extension_then_brakes_until_the_car_stands",
            "a_campaign_runs_through_a_tapped_vehicle_as_the_runner_promises",
            "sigterm_stops_the_car_safely_and_completes_the_run_directory",
        ],
    ),
    (
        "Every session on a car ends with its faults cleared",
        &[
            "a_campaign_that_ends_leaves_the_car_disarmed",
            "an_interrupted_campaign_leaves_the_car_disarmed",
            "the_dry_run_that_does_not_recognise_a_fault_reply_says_it_and_disarms",
            "a_car_that_cannot_be_reached_is_named_armed",
        ],
    ),
    (
        "In virtual time the same seed gives byte-identical case files",
        &[
            "the_same_seed_gives_identical_case_files",
            "the_same_seed_records_the_same_messages",
            "two_jobs_and_two_merged_shards_give_the_serial_runs_case_files",
        ],
    ),
    (
        "The simulated car never reads the wall clock",
        &[
            "the_simulated_car_reads_no_wall_clock",
            "the_same_seed_gives_identical_replies_in_virtual_time",
        ],
    ),
    (
        "Library crates return typed errors",
        &[
            "library_crates_return_typed_errors",
            "the_decoder_never_panics",
            "the_scenario_and_case_parsers_take_any_text",
        ],
    ),
    (
        "Every JSON, TOML, XML and HTML file drivecheck writes is written whole",
        &[
            "the_file_is_replaced_whole_and_no_temporary_file_is_left",
            "a_staged_directory_appears_whole_or_not_at_all",
        ],
    ),
    (
        "No command leaves a scratch file behind",
        &[
            "remove_all_removes_what_is_registered_and_nothing_else",
            "a_dead_processs_scratch_is_removed_and_a_live_ones_and_other_files_are_not",
            "a_report_interrupted_by_sigint_exits_2_and_leaves_nothing_behind",
            "runs_merge_interrupted_by_sigterm_exits_2_and_leaves_no_staging_directory",
            "a_report_removes_what_a_killed_process_left_and_says_so",
            "resume_removes_the_temporary_file_of_a_killed_process",
        ],
    ),
    (
        "The runner and the commands drive a car only through the trait",
        &[
            "only_the_seam_names_a_concrete_car",
            "a_campaign_runs_through_a_tapped_vehicle_as_the_runner_promises",
        ],
    ),
    (
        "Exit statuses are",
        &[
            "only_exit_ends_the_process",
            "the_codes_are_the_documented_ones",
        ],
    ),
    ("Nothing reads", &["nothing_reads_the_shared_folder"]),
    (
        "A crate uses only the crates of the layers below it",
        &["each_crate_uses_only_lower_layers"],
    ),
    (
        "The report calls no command",
        &["the_report_calls_no_command"],
    ),
    (
        "The vehicle seam uses nothing of the runner",
        &["the_vehicle_seam_uses_nothing_of_the_runner"],
    ),
    (
        "tokio's pausable clock is a normal dependency only",
        &["the_pausable_clock_is_where_virtual_time_runs"],
    ),
    (
        "Every point the generator returns passes",
        &[
            "every_extension_keeps_the_constraints",
            "the_same_seed_gives_the_same_trajectory",
        ],
    ),
    (
        "Every returned route plus its joint passes",
        &[
            "dubins_routes_from_clear_poses_are_drivable_in_every_real_area",
            "reference_routes_from_clear_poses_are_drivable_in_every_real_area",
        ],
    ),
    (
        "The canonical form writes a fault kind's range only",
        &["the_canonical_toml_of_imported_reference_xml"],
    ),
    (
        "Every reply is matched to its request",
        &[
            "stray_and_duplicate_replies_are_not_taken_for_answers",
            "the_keepalive_feeds_the_watchdog_while_the_car_is_alive",
            "a_silent_car_times_out_instead_of_answering_zeros",
        ],
    ),
    (
        "Every way a simulated car differs from its scenario's default car",
        &[
            "what_a_file_leaves_out_is_the_default_car",
            "the_documented_default_profile_is_the_default_car_in_canonical_form",
        ],
    ),
    (
        "One integration-test binary per crate",
        &["one_integration_test_binary_per_crate"],
    ),
    (
        "campaign's top-level modules have no dependency cycle",
        &["campaigns_top_level_modules_have_no_cycle"],
    ),
];

/// The bold statements of the sections that state invariants.
fn bold_invariants(architecture: &str) -> Vec<String> {
    let mut found = Vec::new();
    for section in architecture.split("\n## ").skip(1) {
        let title = section.lines().next().unwrap_or("");
        if ![
            "Invariants",
            "Code map",
            "Files and their versions",
            "Layers",
        ]
        .iter()
        .any(|t| title.starts_with(t))
        {
            continue;
        }
        for (i, part) in section.split("**").enumerate() {
            if i % 2 == 1 {
                found.push(part.split_whitespace().collect::<Vec<_>>().join(" "));
            }
        }
    }
    found
}

/// Every test function's name in the workspace.
fn test_names() -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for (_, text) in rust_files(".") {
        for line in text.lines() {
            let line = line.trim_start();
            let line = line.strip_prefix("async ").unwrap_or(line);
            if let Some(rest) = line.strip_prefix("fn ") {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                names.insert(name);
            }
        }
    }
    names
}

/// Every invariant ARCHITECTURE.md states in bold names the tests that check it, and they exist.
#[test]
fn every_bold_invariant_is_checked_by_a_test() {
    let text = fs::read_to_string(workspace().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let invariants = bold_invariants(&text);
    assert!(invariants.len() >= 15, "too few found: {invariants:?}");
    let names = test_names();
    let mut problems = Vec::new();
    for invariant in &invariants {
        match CHECKED_BY
            .iter()
            .find(|(start, _)| invariant.starts_with(start))
        {
            None => problems.push(format!("no test named for: {invariant}")),
            Some((_, tests)) => {
                for test in *tests {
                    if !names.contains(*test) {
                        problems.push(format!("{invariant}: no test `{test}`"));
                    }
                }
            }
        }
    }
    for (start, _) in CHECKED_BY {
        if !invariants.iter().any(|i| i.starts_with(start)) {
            problems.push(format!(
                "CHECKED_BY names an invariant ARCHITECTURE.md no longer states: {start}"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
