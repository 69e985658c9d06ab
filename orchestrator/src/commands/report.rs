//! `drivecheck report RUN_DIR`: the self-contained HTML page of a run, replay or shrink
//! directory ([`report`]); also what `run --report` and `replay --report` call at the end.

use std::path::Path;

use anyhow::Result;

use crate::cli::ReportArgs;
use crate::exit::Exit;
use crate::scenario_arg::optional_scenario;
use report::{self, REPORT_FILE, ReportKind, ReportOptions};

/// Writes the report. Exit status 0, or 2 on an error (not a run directory, a file that cannot
/// be read or written).
pub fn report(args: &ReportArgs) -> Result<Exit> {
    let scenario = optional_scenario(args.scenario.as_deref())?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.dir.join(REPORT_FILE));
    // A report replaces a report, never a recorded file (`--out RUN/case-001.json`).
    let is_html = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("html") || e.eq_ignore_ascii_case("htm"));
    if out.exists() && !is_html {
        anyhow::bail!(
            "--out {}: the file exists and is not an HTML report; give another path",
            out.display()
        );
    }
    let options = ReportOptions {
        all_tests: args.all_tests,
    };
    write(&args.dir, &out, scenario.as_ref(), &options)?;
    Ok(Exit::Success)
}

/// Writes `dir`'s report to `out` and says so on standard error.
pub(super) fn write(
    dir: &Path,
    out: &Path,
    scenario: Option<&scenarios::Scenario>,
    options: &ReportOptions,
) -> Result<()> {
    // What a report or a campaign killed while writing left here (`kill -9`: the sections put
    // aside, a temporary file) is nobody's: removed, with a note.
    let ours = [
        runner::CAMPAIGN_FILE,
        campaign::replay::REPLAY_FILE,
        campaign::shrink::SHRINK_FILE,
    ]
    .iter()
    .any(|file| dir.join(file).is_file());
    if ours {
        super::signals::note_leftovers(runner::scratch::clear_leftovers(dir));
    }
    super::signals::note_leftovers(runner::scratch::clear_leftovers_of(out));
    let pages = out.with_extension("");
    if pages.is_dir() {
        super::signals::note_leftovers(runner::scratch::clear_leftovers(&pages));
    }
    let written = report::write(dir, out, scenario, options)?;
    let items = match written.kind {
        ReportKind::Campaign if written.pages > 0 => format!(
            "{} tests, {} drawn on {} pages in {}",
            written.items,
            written.sections,
            written.pages,
            out.with_extension("").display()
        ),
        ReportKind::Campaign => format!("{} tests, {} drawn", written.items, written.sections),
        ReportKind::Replay => format!("{} runs", written.items),
        ReportKind::Shrink => format!("{} steps, no maps", written.items),
    };
    crate::output::note(format_args!(
        "report: {} ({items}, {:.1} kB)",
        written.path.display(),
        written.bytes as f64 / 1000.0
    ));
    Ok(())
}
