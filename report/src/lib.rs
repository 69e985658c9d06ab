//! `report.html`: a self-contained page of a run directory (`drivecheck report`, `run --report`,
//! `replay --report`), readable from a file without network or script.
//!
//! - A campaign's run directory: a summary (seed, scenario, tool, car and firmware, the verdict
//!   counts, the worst deviation, wall and driven time), a table of every test (a row each), and
//!   for each test that did not pass (every test with `--all-tests`) a section linked from its
//!   row: a map (fence, cutouts, anchors, the planned route, the RTK track and the UWB track
//!   coloured by deviation, where each fault was added and where it acted) and a plot of the
//!   deviation against time (threshold, segment boundaries, the faults' windows), with its
//!   segments and faults as tables. Written a test at a time (`campaign`); more than 100
//!   sections go to pages of their own beside the index.
//! - A replay directory: the runs on one map, a plot per run, the per-segment comparison.
//! - A shrink directory: the before/after and steps tables (no pictures: its runs are not
//!   recorded).
//!
//! The tracks come from the recording's `/car/state` samples, split by the `/tests` events and
//! timed on the test's clock (see `data`); the pictures are drawn with `plotters`' SVG backend
//! (`draw`) and put inline into the page (`html`). The scenario for the maps is the one the
//! caller gives, else the recording's copy, else the bundled scenario of the record's name.
//!
//! `compare.html` (`drivecheck compare --report`, `compare`) is the page of two runs compared, in
//! the same style.
//!
//! Not here: reading the command line (`commands::report`).

mod campaign;
pub mod compare;
pub mod data;
mod draw;
pub mod explain;
mod html;
mod labels;
mod route;
pub mod svg;

use std::path::{Path, PathBuf};

use scenarios::Scenario;
use thiserror::Error;

use data::{Directory, scenario_for};

/// The report's file name in the directory it describes.
pub const REPORT_FILE: &str = "report.html";

/// Why a report could not be written.
#[derive(Debug, Error)]
pub enum ReportError {
    /// The path is not a directory.
    #[error("{dir} is not a directory")]
    NotADirectory {
        /// The path.
        dir: PathBuf,
    },
    /// The directory holds neither a campaign, a replay nor a shrink.
    #[error(
        "{dir} is not a run directory: it has no campaign.json (nor replay.json or shrink.json)"
    )]
    NotARunDirectory {
        /// The directory.
        dir: PathBuf,
    },
    /// A file could not be read.
    #[error("cannot read {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the system said (in the message, not a source: it would be said twice).
        error: std::io::Error,
    },
    /// A file is not what its name says.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A file of the run directory is refused (a recording of another campaign beside its
    /// cases).
    #[error(transparent)]
    Store(#[from] runner::store::StoreError),
    /// A picture could not be drawn.
    #[error("cannot draw a picture: {0}")]
    Draw(String),
    /// The page could not be written.
    #[error("cannot write {path}: {error}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What the system said (in the message, not a source: it would be said twice).
        error: std::io::Error,
    },
}

/// What kind of directory a report describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReportKind {
    /// A campaign's run directory (or one run of a replay).
    Campaign,
    /// A replay directory.
    Replay,
    /// A shrink directory.
    Shrink,
}

/// What a report shows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReportOptions {
    /// A campaign's page holds every test's section (maps, plot, tables), not only the failing,
    /// aborted and not run tests'.
    pub all_tests: bool,
}

/// A report written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    /// Where.
    pub path: PathBuf,
    /// Its size, bytes (its pages' too).
    pub bytes: u64,
    /// What it describes.
    pub kind: ReportKind,
    /// Tests (campaign) or runs (replay) shown; steps for a shrink.
    pub items: usize,
    /// A campaign's tests with a section (maps, plot, tables).
    pub sections: usize,
    /// A campaign's pages of sections besides the index page, in the directory named as the
    /// page without its extension (`report/tests-0001.html`, …); 0 when the sections are on
    /// the page itself.
    pub pages: usize,
}

/// Writes the page of directory `dir` (see the module doc) to `out`. `scenario`, when given, is
/// the scenario to draw the maps in (checked against the recorded hash: a mismatch is noted on
/// the page). A campaign's page is written a test at a time (`campaign`); a replay's and a
/// shrink's, of a case each, at once.
pub fn write(
    dir: &Path,
    out: &Path,
    scenario: Option<&Scenario>,
    options: &ReportOptions,
) -> Result<Written, ReportError> {
    let directory = Directory::read(dir)?;
    let (page, kind, items) = match directory {
        Directory::Campaign => {
            let pages = campaign::write(dir, out, scenario, options)?;
            return Ok(Written {
                path: out.to_owned(),
                bytes: pages.bytes,
                kind: ReportKind::Campaign,
                items: pages.tests,
                sections: pages.sections,
                pages: pages.pages,
            });
        }
        Directory::Replay(data) => {
            let recorded = data
                .runs
                .iter()
                .find_map(|(_, d)| d.as_ref()?.recorded_scenario.clone());
            let c = &data.comparison;
            let (scenario, notes) = scenario_for(
                &c.scenario.name,
                c.scenario.hash.as_deref(),
                scenario,
                recorded.as_deref(),
            );
            let page = html::replay_page(&data, scenario.as_ref(), notes)?;
            (page, ReportKind::Replay, data.runs.len())
        }
        Directory::Shrink(data) => {
            let steps = data.report.steps.len();
            (
                html::shrink_page(&data, Vec::new()),
                ReportKind::Shrink,
                steps,
            )
        }
    };
    runner::atomic::write(out, &page).map_err(|error| ReportError::Write {
        path: out.to_owned(),
        error,
    })?;
    Ok(Written {
        path: out.to_owned(),
        bytes: page.len() as u64,
        kind,
        items,
        sections: 0,
        pages: 0,
    })
}
