//! The exit status, end to end: the binary's status is `orchestrator::exit::Exit`'s table for the
//! command lines clap handles and for a few commands, every command's `--help` says its statuses,
//! and README.md's table is the type's.

use crate::common;

use clap::CommandFactory;
use common::{drivecheck, path, text};
use orchestrator::cli::Cli;
use orchestrator::exit::Exit;

fn status(args: &[&str]) -> (Option<i32>, String) {
    let out = drivecheck(args);
    (out.status.code(), text(&out))
}

fn code(exit: Exit) -> Option<i32> {
    Some(i32::from(exit.code()))
}

fn fixture(name: &str) -> String {
    format!("{}/../tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn a_command_line_that_does_not_parse_is_an_error_and_help_is_not() {
    for args in [
        &["run", "--no-such-option"][..],
        &["no-such-command"],
        &["run", "--tests", "0"],
        &[],
    ] {
        let (status, log) = status(args);
        assert_eq!(status, code(Exit::Error), "{args:?}: {log}");
    }
    for args in [&["--help"][..], &["run", "--help"], &["--version"]] {
        let (status, log) = status(args);
        assert_eq!(status, code(Exit::Success), "{args:?}: {log}");
    }
}

#[test]
fn the_help_shows_the_table() {
    let out = drivecheck(&["--help"]);
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains(&Exit::help()), "{help}");
}

#[test]
fn scenario_commands_exit_zero_when_done_and_two_on_an_invalid_file() {
    assert_eq!(status(&["scenario", "list"]).0, code(Exit::Success));
    assert_eq!(
        status(&["scenario", "check", "courtyard"]).0,
        code(Exit::Success)
    );
    let (invalid, log) = status(&[
        "scenario",
        "check",
        &fixture("malformed/unknown-field.toml"),
    ]);
    assert_eq!(invalid, code(Exit::Error), "{log}");
    let (import, log) = status(&["scenario", "import", &fixture("xml/courtyard.xml")]);
    assert_eq!(import, code(Exit::Success), "{log}");
    let (bad_xml, log) = status(&[
        "scenario",
        "import",
        &fixture("malformed/xml-syntax-error.xml"),
    ]);
    assert_eq!(bad_xml, code(Exit::Error), "{log}");
}

#[test]
fn reading_commands_exit_two_on_what_is_not_a_run_directory() {
    let dir = tempfile::tempdir().unwrap();
    let (listed, log) = status(&["runs", "--dir", path(dir.path())]);
    assert_eq!(listed, code(Exit::Success), "{log}");
    for args in [
        &["report", path(dir.path())][..],
        &["explain", path(dir.path())],
        &["runs", "show", path(dir.path())],
    ] {
        let (status, log) = status(args);
        assert_eq!(status, code(Exit::Error), "{args:?}: {log}");
    }
}

/// Every command that does something (not a group that only holds subcommands) says its exit
/// statuses in its help.
#[test]
fn every_command_documents_its_exit_status() {
    let mut root = Cli::command();
    root.build();
    let mut missing = Vec::new();
    let mut stack: Vec<(String, &clap::Command)> = root
        .get_subcommands()
        .map(|c| (c.get_name().to_owned(), c))
        .collect();
    while let Some((name, command)) = stack.pop() {
        // clap's own `help` subcommands print help and exit 0.
        if command.get_name() == "help" {
            continue;
        }
        let only_a_group = command.is_subcommand_required_set();
        let help = command
            .get_long_about()
            .or(command.get_about())
            .map(ToString::to_string)
            .unwrap_or_default();
        if !only_a_group && !help.contains("Exit status") && !help.contains("Exit\nstatus") {
            missing.push(name.clone());
        }
        stack.extend(
            command
                .get_subcommands()
                .map(|c| (format!("{name} {}", c.get_name()), c)),
        );
    }
    assert!(missing.is_empty(), "no exit status in --help: {missing:?}");
}

#[test]
fn the_readme_table_is_the_types() {
    let readme = std::fs::read_to_string(format!("{}/../README.md", env!("CARGO_MANIFEST_DIR")))
        .expect("README.md");
    for exit in Exit::ALL {
        let row = format!(
            "| {} | `{exit:?}` | {} |",
            exit.code(),
            exit.meaning().replace('|', "\\|")
        );
        assert!(readme.contains(&row), "README.md has no row {row}");
    }
}
