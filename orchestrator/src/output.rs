//! How much a command prints: `-q/--quiet` (the summary and errors), the default, or
//! `-v/--verbose` (every test, every warning). Set once from the command line, read where a
//! command prints.

use std::sync::atomic::{AtomicU8, Ordering};

use serde::Serialize;

/// How much a command prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Verbosity {
    /// The summary and errors only.
    Quiet,
    /// Progress, notes, the tests that did not pass.
    Normal,
    /// Every test, every warning.
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

/// Whether progress and notes are printed (not `--quiet`).
pub fn chatty() -> bool {
    verbosity() >= Verbosity::Normal
}

/// The version of the documents `--json` prints (docs/json.md): bumped when a field is removed,
/// renamed or changes meaning, not when one is added.
pub const JSON_SCHEMA_VERSION: u32 = 1;

/// What `--json` prints: the command's name and [`JSON_SCHEMA_VERSION`], then its result's fields.
#[derive(Serialize)]
struct Document<'a, T> {
    /// The command (`run`, `runs show`, …).
    command: &'a str,
    /// [`JSON_SCHEMA_VERSION`].
    schema_version: u32,
    /// The result's own fields.
    #[serde(flatten)]
    result: &'a T,
}

/// Prints `result` of `command` as one JSON document on standard output (`--json`): an object
/// with `command`, `schema_version` and the result's fields (docs/json.md).
pub fn print_json<T: Serialize>(command: &str, result: &T) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(&Document {
        command,
        schema_version: JSON_SCHEMA_VERSION,
        result,
    })?;
    println!("{text}");
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
}
