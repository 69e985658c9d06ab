//! A campaign's report, written a test at a time so that its memory does not grow with the
//! campaign: the case files give the tests table, the summary and the coverage (read one at a
//! time, a row kept per test); then the recording is read a span (a test's messages) at a time,
//! and each test that gets a section (failed, aborted or not run; every test with
//! [`ReportOptions::all_tests`]) has its case read again, its track split, its section drawn and
//! put aside in a file beside the page; the page is then written from those pieces in test
//! order. More than [`PAGE_TESTS`] sections go to pages of their own, linked from the index page.
//! Every file is written whole or not at all (`atomic::Staged`), the pages before the index.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use scenarios::Scenario;

use super::data::{
    TestData, Tracks, case_files, read_case, read_record, read_rows, read_spans, read_twin,
    scenario_for,
};
use super::html::{
    CampaignTop, campaign_top, coverage_section, foot, pages_section, section_page_top,
    test_section,
};
use super::{ReportError, ReportOptions};
use campaign::coverage::CoverageBuilder;
use campaign::oracle::Verdict;
use runner::atomic::Staged;
use runner::scratch::Scratch;

/// The most test sections one page holds: a failing test's section is about 90 kB (a map and a
/// plot of up to 2000 samples each), so a page stays under about 10 MB; a campaign with more
/// sections gets an index page and pages of sections (`report/tests-0001.html`, …).
pub const PAGE_TESTS: usize = 100;

/// What was written.
pub struct Pages {
    /// Tests in the campaign.
    pub tests: usize,
    /// Tests with a section.
    pub sections: usize,
    /// Pages of sections besides the index page (0: the sections are on the index page).
    pub pages: usize,
    /// Bytes written, all pages.
    pub bytes: u64,
}

/// Writes the report of the campaign in `dir` to `out` (and, with more than [`PAGE_TESTS`]
/// sections, its pages into the directory named as `out` without its extension).
pub fn write(
    dir: &Path,
    out: &Path,
    given: Option<&Scenario>,
    options: &ReportOptions,
) -> Result<Pages, ReportError> {
    let record = read_record(dir)?;
    let rows = read_rows(dir, |_| {})?;
    let files: BTreeMap<usize, String> = rows.iter().map(|r| (r.index, r.file.clone())).collect();
    let wanted: BTreeSet<usize> = rows
        .iter()
        .filter(|r| options.all_tests || r.verdict != Some(Verdict::Passed))
        .map(|r| r.index)
        .collect();
    let threshold = record.settings.oracle_threshold_m;
    let mut spill = Spill::create(out)?;
    let mut notes = Vec::new();
    let mut chosen: Option<(Option<Scenario>, Vec<String>)> = None;
    let pick = |recorded: Option<&str>| {
        scenario_for(
            &record.scenario.name,
            record.scenario.hash.as_deref(),
            given,
            recorded,
        )
    };
    let section = |spill: &mut Spill,
                   scenario: Option<&Scenario>,
                   index: usize,
                   track|
     -> Result<(), ReportError> {
        let file = &files[&index];
        let test = TestData {
            index,
            file: file.clone(),
            case: read_case(dir, file)?,
            track,
        };
        let mut html = String::new();
        test_section(
            &mut html,
            &format!("test-{index:03}"),
            &format!("Test {index:03}"),
            &test,
            scenario,
            threshold,
            true,
        )?;
        spill.put(index, &html)?;
        runner::pause_at("report", index);
        Ok(())
    };
    let recorded = read_spans(dir, None, &mut notes, |test, recording, recorded, notes| {
        let (scenario, _) = chosen.get_or_insert_with(|| pick(recorded));
        // A test's span gives its track; one no test claims (a car recorded for the whole
        // campaign) any test's it holds.
        let targets: Vec<usize> = match test.filter(|t| files.contains_key(t)) {
            Some(t) => vec![t],
            None => wanted.iter().copied().collect(),
        };
        let targets: Vec<usize> = targets
            .into_iter()
            .filter(|t| wanted.contains(t) && !spill.has(*t))
            .collect();
        if targets.is_empty() {
            return Ok(());
        }
        let tracks = match Tracks::split(&recording) {
            Ok(tracks) => tracks,
            Err(e) => {
                notes.push(format!(
                    "{}: {e}; no tracks or plots",
                    dir.join(runner::RECORDING_FILE).display()
                ));
                return Ok(());
            }
        };
        drop(recording);
        for index in targets {
            if let Some(track) = tracks.track(index) {
                section(&mut spill, scenario.as_ref(), index, Some(track))?;
            }
        }
        Ok(())
    })?;
    let (scenario, mut page_notes) = chosen.unwrap_or_else(|| pick(recorded.as_deref()));
    // The tests the recording has no track of: their tables, and the map without tracks.
    for &index in &wanted {
        if !spill.has(index) {
            section(&mut spill, scenario.as_ref(), index, None)?;
        }
    }
    // The coverage: every case file again, one at a time.
    let coverage = match &scenario {
        Some(s) => {
            let mut builder = CoverageBuilder::of_scenario(s);
            for (_, file) in case_files(dir)? {
                builder.add(&read_case(dir, &file)?);
            }
            Some(builder.finish())
        }
        None => None,
    };
    let twin = read_twin(dir, &mut notes);
    page_notes.extend(notes);

    // The layout: the sections on the index page, or on pages of `PAGE_TESTS`.
    let order: Vec<usize> = wanted.iter().copied().collect();
    let split = order.len() > PAGE_TESTS;
    let pages_dir = out.with_extension("");
    let pages_name = pages_dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "report".to_owned());
    let index_name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let chunks: Vec<&[usize]> = if split {
        order.chunks(PAGE_TESTS).collect()
    } else {
        Vec::new()
    };
    let page_file = |page: usize| format!("tests-{page:04}.html");
    let page_of: BTreeMap<usize, usize> = chunks
        .iter()
        .enumerate()
        .flat_map(|(k, chunk)| chunk.iter().map(move |&t| (t, k + 1)))
        .collect();
    let mut bytes = 0;
    if split {
        if pages_dir.exists() && !pages_dir.is_dir() {
            return Err(write_error(
                &pages_dir,
                std::io::Error::other("it exists and is not a directory"),
            ));
        }
        std::fs::create_dir_all(&pages_dir).map_err(|e| write_error(&pages_dir, e))?;
        for (k, chunk) in chunks.iter().enumerate() {
            let path = pages_dir.join(page_file(k + 1));
            let mut head = String::new();
            section_page_top(
                &mut head,
                &record,
                &format!("../{index_name}"),
                (k + 1, chunks.len()),
                (chunk[0], chunk[chunk.len() - 1]),
                page_file,
            );
            let mut foot_html = String::new();
            foot(&mut foot_html, dir);
            bytes += write_page(&path, &head, chunk, &mut spill, &foot_html)?;
        }
    }
    let mut top = String::new();
    campaign_top(
        &mut top,
        &CampaignTop {
            dir,
            record: &record,
            rows: &rows,
            twin: twin.as_ref(),
            notes: &page_notes,
        },
        |t| {
            if split {
                page_of
                    .get(&t)
                    .map(|p| format!("{pages_name}/{}#test-{t:03}", page_file(*p)))
            } else {
                wanted.contains(&t).then(|| format!("#test-{t:03}"))
            }
        },
    );
    if split {
        let list: Vec<(String, usize, usize, usize)> = chunks
            .iter()
            .enumerate()
            .map(|(k, c)| {
                (
                    format!("{pages_name}/{}", page_file(k + 1)),
                    c[0],
                    c[c.len() - 1],
                    c.len(),
                )
            })
            .collect();
        pages_section(&mut top, &list);
    }
    coverage_section(&mut top, scenario.as_ref(), coverage.as_ref())?;
    drop(coverage);
    let mut foot_html = String::new();
    foot(&mut foot_html, dir);
    let on_index: &[usize] = if split { &[] } else { &order };
    bytes += write_page(out, &top, on_index, &mut spill, &foot_html)?;
    remove_stale_pages(&pages_dir, chunks.len());
    Ok(Pages {
        tests: rows.len(),
        sections: order.len(),
        pages: chunks.len(),
        bytes,
    })
}

fn write_error(path: &Path, error: std::io::Error) -> ReportError {
    ReportError::Write {
        path: path.to_owned(),
        error,
    }
}

/// Writes the page `path`: `head`, the sections of `tests` from `spill`, `foot`; its size.
fn write_page(
    path: &Path,
    head: &str,
    tests: &[usize],
    spill: &mut Spill,
    foot: &str,
) -> Result<u64, ReportError> {
    let io = |e| write_error(path, e);
    let mut page = Staged::create(path).map_err(io)?;
    page.write_all(head.as_bytes()).map_err(io)?;
    let mut bytes = head.len() as u64;
    for &t in tests {
        bytes += spill.copy(t, &mut page).map_err(io)?;
    }
    page.write_all(foot.as_bytes()).map_err(io)?;
    page.commit().map_err(io)?;
    Ok(bytes + foot.len() as u64)
}

/// Removes the pages of sections numbered above `keep` (an earlier report's, of more tests),
/// and the directory when it is left empty.
fn remove_stale_pages(pages_dir: &Path, keep: usize) {
    let Ok(entries) = std::fs::read_dir(pages_dir) else {
        return;
    };
    for entry in entries.filter_map(Result::ok) {
        let name = entry.file_name().to_string_lossy().into_owned();
        let number = name
            .strip_prefix("tests-")
            .and_then(|n| n.strip_suffix(".html"))
            .and_then(|n| n.parse::<usize>().ok());
        if number.is_some_and(|n| n > keep) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
    let _ = std::fs::remove_dir(pages_dir);
}

/// The sections drawn so far, in a file beside the page (removed when dropped): the recording
/// gives tests in the order they ended, the page wants them in test order.
/// The file is this process's scratch (`runner::scratch`): a signal removes it, and one a
/// `kill -9` left is removed by the next report beside it.
struct Spill {
    file: File,
    path: PathBuf,
    end: u64,
    at: BTreeMap<usize, (u64, u64)>,
    _scratch: Scratch,
}

impl Spill {
    fn create(out: &Path) -> Result<Self, ReportError> {
        let path = runner::scratch::beside(out, "sections");
        let (scratch, file) = Scratch::create(&path, |path| {
            File::options()
                .read(true)
                .write(true)
                .create(true)
                .truncate(true)
                .open(path)
        })
        .map_err(|e| write_error(&path, e))?;
        Ok(Self {
            file,
            path,
            end: 0,
            at: BTreeMap::new(),
            _scratch: scratch,
        })
    }

    fn has(&self, test: usize) -> bool {
        self.at.contains_key(&test)
    }

    fn put(&mut self, test: usize, html: &str) -> Result<(), ReportError> {
        let result = (|| {
            self.file.seek(SeekFrom::Start(self.end))?;
            self.file.write_all(html.as_bytes())
        })();
        result.map_err(|e| write_error(&self.path, e))?;
        self.at.insert(test, (self.end, html.len() as u64));
        self.end += html.len() as u64;
        Ok(())
    }

    /// Copies test `test`'s section to `to`; its length.
    fn copy(&mut self, test: usize, to: &mut impl Write) -> std::io::Result<u64> {
        let Some(&(from, len)) = self.at.get(&test) else {
            return Ok(0);
        };
        self.file.seek(SeekFrom::Start(from))?;
        std::io::copy(&mut (&mut self.file).take(len), to)
    }
}

impl Drop for Spill {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}
