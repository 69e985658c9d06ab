//! How much a command prints: `-q/--quiet` (the summary and errors), the default, or
//! `-v/--verbose` (every test, every warning). Set once from the command line, read where a
//! command prints.

use std::sync::atomic::{AtomicU8, Ordering};

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
