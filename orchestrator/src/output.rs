//! What `drivecheck` prints, decided in one place for every command:
//!
//! - on standard error, at each verbosity (`-q/--quiet`, the default, `-v/--verbose`): every line
//!   a command writes there is one of [`Says`]'s kinds, printed by [`say`] (or a progress bar of
//!   [`bar`], an observer's line tested with [`shows`]); errors are `process::main`'s, always;
//! - on standard output with `--json`: one document in the envelope every command shares
//!   ([`print_json`]: `command`, `schema_version`, then the result; [`json`] lists them all).
//!
//! The verbosity is set once from the command line (`process::main`). What `-q` and `-v` do for
//! each command is in its `--help` (`cli::VERBOSITY`); the end-to-end test `quiet_everywhere`
//! runs every command with `-q` and holds it to this module.

use std::fmt::Display;
use std::sync::atomic::{AtomicU8, Ordering};

use serde::Serialize;

/// How much a command prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Verbosity {
    /// The result, errors and safety warnings only (`-q`).
    Quiet,
    /// Progress, notes, warnings, the tests that did not pass.
    Normal,
    /// Every test, and the details that are the same on every run (`-v`).
    Verbose,
}

static VERBOSITY: AtomicU8 = AtomicU8::new(1);

/// Sets the process's verbosity (`main`, from `-q` and `-v`).
pub fn set(verbosity: Verbosity) {
    VERBOSITY.store(verbosity as u8, Ordering::Relaxed);
}

/// The process's verbosity.
pub fn verbosity() -> Verbosity {
    match VERBOSITY.load(Ordering::Relaxed) {
        0 => Verbosity::Quiet,
        1 => Verbosity::Normal,
        _ => Verbosity::Verbose,
    }
}

/// What a line on standard error is: its kind decides at which verbosity it is printed
/// ([`Says::shown_at`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Says {
    /// How far the command is: a campaign's line per test, `run 1/3: passed`, `sweeping …`, a
    /// progress bar. Not with `-q`.
    Progress,
    /// What is worth knowing and not a problem: the seed chosen, a file written, how a file's
    /// coordinates were read, where a live view listens. Not with `-q`.
    Note,
    /// A problem with what the command was given that does not stop it: a scenario file's drawing
    /// warnings, a scenario hash ignored (`--ignore-scenario-hash`), a case recorded on another
    /// car profile, failures that could not be explained. Not with `-q`.
    Warning,
    /// What is the same on every run, said only when asked (`-v`): a bundled scenario's drawing
    /// warnings (data the user cannot change; `scenario check -v NAME` shows them), the fields
    /// preflight switches off on the simulated car.
    Detail,
    /// Why the command exits 1 when its result on standard output does not say: no return route
    /// from the pose (`route return`), a case that does not fail the same way every time
    /// (`shrink`). Always, as errors are.
    Finding,
    /// What the operator must know about a car whatever `-q` says: a car left with fault
    /// injection enabled (`runner/src/session_end.rs`), what a signal does (stopping, braking), a
    /// brake that could not be sent. Always: the exception to `-q` by design.
    Safety,
}

impl Says {
    /// Whether a line of this kind is printed at `verbosity`.
    pub fn shown_at(self, verbosity: Verbosity) -> bool {
        match self {
            Says::Progress | Says::Note | Says::Warning => verbosity >= Verbosity::Normal,
            Says::Detail => verbosity == Verbosity::Verbose,
            Says::Finding | Says::Safety => true,
        }
    }
}

/// Whether a line of kind `kind` is printed at the process's verbosity.
pub fn shows(kind: Says) -> bool {
    kind.shown_at(verbosity())
}

/// Prints `text` on standard error, as it is, when the process's verbosity shows `kind`.
pub fn say(kind: Says, text: impl Display) {
    if shows(kind) {
        eprintln!("{text}");
    }
}

/// A [`Says::Progress`] line.
pub fn progress(text: impl Display) {
    say(Says::Progress, text);
}

/// A [`Says::Note`] line.
pub fn note(text: impl Display) {
    say(Says::Note, text);
}

/// A [`Says::Warning`]: `warning: TEXT`.
pub fn warning(text: impl Display) {
    say(Says::Warning, format_args!("warning: {text}"));
}

/// A [`Says::Safety`] line: printed whatever the verbosity.
pub fn safety(text: impl Display) {
    say(Says::Safety, text);
}

/// A [`Says::Finding`] line: printed whatever the verbosity.
pub fn finding(text: impl Display) {
    say(Says::Finding, text);
}

/// A progress bar of `len` steps (a spinner when `None`) on standard error: hidden with `-q`
/// ([`Says::Progress`]; indicatif itself draws nothing when standard error is not a terminal).
pub fn bar(len: Option<u64>) -> indicatif::ProgressBar {
    if !shows(Says::Progress) {
        return indicatif::ProgressBar::hidden();
    }
    match len {
        Some(len) => indicatif::ProgressBar::new(len),
        None => indicatif::ProgressBar::new_spinner(),
    }
}

/// The `--json` documents: what each is named by (its `command`) and its schema version.
pub mod json {
    /// A `--json` document: its `command` (the command as typed, with the option that gives the
    /// document another shape: `run --dry-run`, `explain --score`) and its `schema_version`, the
    /// document's own: it goes up when one of its fields is removed, renamed or changes meaning,
    /// not when one is added (docs/json.md).
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Document {
        /// The command, as `command` says it.
        pub command: &'static str,
        /// Its schema version.
        pub schema_version: u32,
    }

    const fn doc(command: &'static str, schema_version: u32) -> Document {
        Document {
            command,
            schema_version,
        }
    }

    /// `run`: the run directory, `campaign.json`'s record, every test.
    pub const RUN: Document = doc("run", 1);
    /// `run --dry-run`: what the car's check found.
    pub const RUN_DRY_RUN: Document = doc("run --dry-run", 1);
    /// `runs`: the run directories.
    pub const RUNS: Document = doc("runs", 1);
    /// `runs show`: one run directory.
    pub const RUNS_SHOW: Document = doc("runs show", 1);
    /// `runs merge`: the merged run directory, as `run`'s.
    pub const RUNS_MERGE: Document = doc("runs merge", 1);
    /// `replay`: the replay directory and `replay.json`.
    pub const REPLAY: Document = doc("replay", 1);
    /// `shrink`: the shrink directory and `shrink.json`.
    pub const SHRINK: Document = doc("shrink", 1);
    /// `sweep`: `sweep` holds the sweep's own document (`drivecheck-sweep`). 2: version 1 was
    /// that document itself, `format` and its own `schema_version` at the top.
    pub const SWEEP: Document = doc("sweep", 2);
    /// `compare`: the comparison.
    pub const COMPARE: Document = doc("compare", 1);
    /// `explain`: the explanations (`cases`). 1: before it, no envelope (the same `cases`).
    pub const EXPLAIN: Document = doc("explain", 1);
    /// `explain --score`: the explanations and their scores.
    pub const EXPLAIN_SCORE: Document = doc("explain --score", 1);
    /// `explain --calibrate`: the nominal level and least growth of a fault-free run.
    pub const EXPLAIN_CALIBRATE: Document = doc("explain --calibrate", 1);
    /// `twin check`: `twin` holds `twin.json` (`drivecheck-twin`). 2: version 1 was `twin.json`
    /// itself, `format` and its own `schema_version` at the top.
    pub const TWIN_CHECK: Document = doc("twin check", 2);
    /// `area validate`: the validation report. 1: before it, no envelope (the same fields).
    pub const AREA_VALIDATE: Document = doc("area validate", 1);
    /// `route generate`: the route. 1: before it, no envelope (the same fields).
    pub const ROUTE_GENERATE: Document = doc("route generate", 1);
    /// `route return`: the return route. 1: before it, no envelope (the same fields).
    pub const ROUTE_RETURN: Document = doc("route return", 1);
    /// `scenario list`: the bundled scenarios.
    pub const SCENARIO_LIST: Document = doc("scenario list", 1);
    /// `scenario check`: the scenario's summary and warnings.
    pub const SCENARIO_CHECK: Document = doc("scenario check", 1);
    /// `sitl build`: the firmware tree built for the host.
    pub const SITL_BUILD: Document = doc("sitl build", 1);

    /// Every document (docs/json.md has a row for each).
    pub const ALL: &[Document] = &[
        RUN,
        RUN_DRY_RUN,
        RUNS,
        RUNS_SHOW,
        RUNS_MERGE,
        REPLAY,
        SHRINK,
        SWEEP,
        COMPARE,
        EXPLAIN,
        EXPLAIN_SCORE,
        EXPLAIN_CALIBRATE,
        TWIN_CHECK,
        AREA_VALIDATE,
        ROUTE_GENERATE,
        ROUTE_RETURN,
        SCENARIO_LIST,
        SCENARIO_CHECK,
        SITL_BUILD,
    ];
}

/// What `--json` prints: the document's `command` and `schema_version`, then its result's fields.
#[derive(Serialize)]
struct Envelope<'a, T> {
    /// The command (`run`, `runs show`, …).
    command: &'a str,
    /// The document's schema version.
    schema_version: u32,
    /// The result's own fields.
    #[serde(flatten)]
    result: &'a T,
}

/// The text of `result` as document `document` (see [`print_json`]).
pub fn json_text<T: Serialize>(document: json::Document, result: &T) -> anyhow::Result<String> {
    let text = serde_json::to_string_pretty(&Envelope {
        command: document.command,
        schema_version: document.schema_version,
        result,
    })?;
    // Flattened, a result that repeats the envelope's keys would print them twice, and a reader
    // would keep one or the other. Checked where tests run (a debug build): the documents' shapes
    // are the same in every build.
    if cfg!(debug_assertions) {
        let value: serde_json::Value = serde_json::from_str(&text)?;
        anyhow::ensure!(
            value["command"] == document.command
                && value["schema_version"] == document.schema_version,
            "the JSON document of `{}` repeats its envelope's keys",
            document.command
        );
    }
    Ok(text)
}

/// Prints `result` as one JSON document on standard output (`--json`): an object with
/// `command`, `schema_version` and the result's fields (docs/json.md), the same envelope for
/// every command.
pub fn print_json<T: Serialize>(document: json::Document, result: &T) -> anyhow::Result<()> {
    println!("{}", json_text(document, result)?);
    Ok(())
}

/// An error and its causes in one line, `outer: inner: …` like anyhow's `{:#}`, without a cause
/// its outer message already ends with (errors that show their source in their own message).
pub fn describe(error: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if line.ends_with(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("not an MCAP file: {0}")]
    struct Shows(#[source] std::io::Error);

    #[test]
    fn a_cause_the_message_already_shows_is_said_once() {
        let error = anyhow::Error::new(Shows(std::io::Error::other("CRC failed"))).context("s2");
        assert_eq!(describe(&error), "s2: not an MCAP file: CRC failed");
        let error = anyhow::anyhow!("inner").context("outer");
        assert_eq!(describe(&error), "outer: inner");
    }

    #[test]
    fn quiet_keeps_findings_and_safety_and_verbose_adds_details() {
        use Says::*;
        let all = [Progress, Note, Warning, Detail, Finding, Safety];
        let shown = |v: Verbosity| {
            all.into_iter()
                .filter(|k| k.shown_at(v))
                .collect::<Vec<_>>()
        };
        assert_eq!(shown(Verbosity::Quiet), [Finding, Safety]);
        assert_eq!(
            shown(Verbosity::Normal),
            [Progress, Note, Warning, Finding, Safety]
        );
        assert_eq!(shown(Verbosity::Verbose), all);
    }

    #[test]
    fn the_envelope_comes_first_and_a_result_cannot_repeat_it() {
        let text = json_text(json::RUN, &serde_json::json!({"dir": "x"})).unwrap();
        assert!(
            text.starts_with("{\n  \"command\": \"run\",\n  \"schema_version\": 1,\n"),
            "{text}"
        );
        assert!(json_text(json::RUN, &serde_json::json!({"command": "other"})).is_err());
        assert!(json_text(json::RUN, &serde_json::json!({"schema_version": 7})).is_err());
        assert!(
            json_text(json::RUN, &[1, 2]).is_err(),
            "a result is an object"
        );
        let commands: std::collections::BTreeSet<_> = json::ALL.iter().map(|d| d.command).collect();
        assert_eq!(commands.len(), json::ALL.len(), "a command is named once");
    }
}
