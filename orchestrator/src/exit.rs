//! The exit status of `drivecheck`: [`Exit`], one table for every command.

use std::process::ExitCode;

/// The exit status of `drivecheck`, the same table for every command (README.md, *Exit status*).
///
/// | status | variant | meaning |
/// |---|---|---|
/// | 0 | [`Exit::Success`] | the command did what it was asked, and what it checked is fine |
/// | 1 | [`Exit::Found`] | the command ran to its end and its check found a problem |
/// | 2 | [`Exit::Error`] | the command could not do its work |
/// | 141 | [`Exit::ClosedStdout`] | the reader of standard output went away (`drivecheck … \| head`) |
///
/// What 0 and 1 mean, command by command:
///
/// | command | 0 | 1 |
/// |---|---|---|
/// | `run` | every test passed | a test failed or was aborted |
/// | `replay` | every run passed | a run failed or was aborted |
/// | `shrink` | shrunk (or minimal already) | the case does not fail the same way in every run: nothing to shrink |
/// | `area validate` | the area is safe | the area is unsafe |
/// | `route return` | a route | no route from the pose (the car must be moved by hand) |
/// | `compare --fail-on regression` | NEW is not significantly worse than BASE | NEW is significantly worse (docs/compare.md) |
/// | every other command | done | (never) |
///
/// 2 is every error: a command line that does not parse (as clap's own status), a scenario or
/// case file that cannot be read or is invalid (so `scenario check` of an invalid scenario), a
/// case refused (another scenario, faults that cannot act), a lost link, a car that refused the
/// preflight, a recording that could not be written, a command interrupted by a signal (SIGINT,
/// SIGTERM, SIGHUP; `commands::signals`).
///
/// `shrink` of a case that does not fail the same way every time exits 1, not 2: nothing went
/// wrong in the tool or its input (the case was read, checked and driven); driving it found that
/// its failure does not reproduce in the simulator (it passes, or fails at segments far apart),
/// which is a finding about the case, as an unsafe area is about the area. A script that shrinks
/// every failed case of a campaign tells that (1) from a broken run (2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Exit {
    /// 0: the command did what it was asked, and what it checked is fine.
    Success = 0,
    /// 1: the command ran to its end and its check found a problem: a failed or aborted test or
    /// run, an unsafe area, no return route, a case whose failure does not reproduce, a
    /// significant regression (`compare --fail-on regression`).
    Found = 1,
    /// 2: the command could not do its work (see the type's doc).
    Error = 2,
    /// 141: standard output was closed by its reader, as a Unix tool killed by SIGPIPE
    /// (128 + 13) reports it.
    ClosedStdout = 141,
}

impl Exit {
    /// Every status, in the order of the table.
    pub const ALL: [Exit; 4] = [Exit::Success, Exit::Found, Exit::Error, Exit::ClosedStdout];

    /// The status as the process reports it.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// What the status means, in a few words (the table's third column).
    pub const fn meaning(self) -> &'static str {
        match self {
            Exit::Success => "the command did what it was asked, and what it checked is fine",
            Exit::Found => "the command ran to its end and its check found a problem",
            Exit::Error => "the command could not do its work",
            Exit::ClosedStdout => {
                "the reader of standard output went away (`drivecheck runs | head`)"
            }
        }
    }

    /// The table as `drivecheck --help` shows it.
    pub fn help() -> String {
        let mut text = String::from("Exit status (every command; see each command's --help):\n");
        for exit in Exit::ALL {
            text.push_str(&format!("  {:>3}  {}\n", exit.code(), exit.meaning()));
        }
        text
    }

    /// Ends the process at once with this status (destructors do not run).
    pub fn exit(self) -> ! {
        std::process::exit(i32::from(self.code()))
    }
}

impl From<Exit> for ExitCode {
    fn from(exit: Exit) -> Self {
        ExitCode::from(exit.code())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_codes_are_the_documented_ones() {
        let codes: Vec<u8> = Exit::ALL.iter().map(|e| e.code()).collect();
        assert_eq!(codes, [0, 1, 2, 141]);
    }

    #[test]
    fn the_help_lists_every_status() {
        let help = Exit::help();
        for exit in Exit::ALL {
            assert!(
                help.contains(&format!("{:>3}  {}", exit.code(), exit.meaning())),
                "{help}"
            );
        }
    }
}
