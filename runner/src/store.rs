//! The run directory's files, named and listed in one place: what a campaign writes into its
//! directory (`campaign.json`, `case-NNN.json`, the partial cases a resume keeps, the recording
//! and the one a resume moves aside, the claim of the process writing it and the space it keeps
//! back for its end) and how a reader finds and reads them (the case files by test index, a case
//! bounded in size). The runner writes through [`RunDirectory`](crate::run_dir); every command
//! and the report find the files here.

use std::path::{Path, PathBuf};

use campaign::files::{Case, CaseError};
use thiserror::Error;

/// The file name of the campaign record in a run directory.
pub const CAMPAIGN_FILE: &str = "campaign.json";
/// The file name of the recording in a run directory.
pub const RECORDING_FILE: &str = "campaign.mcap";
/// The earlier sessions' recording, moved aside while a resumed campaign copies it into the new
/// `campaign.mcap` (removed once copied).
pub const PRIOR_RECORDING_FILE: &str = "campaign.mcap.resumed";
/// The claim of the process writing the directory: its pid (`runner::claim_out_dir`).
pub const CLAIM_FILE: &str = ".drivecheck-writing";
/// Space a campaign keeps back on its disk while it runs (zeros, `runner::run_dir`): given back
/// when the disk is full, so that the session's end is still recorded in `campaign.json`.
pub const RESERVE_FILE: &str = ".drivecheck-reserve";
/// The largest case file read: far above any case a campaign writes (tens of kilobytes), far
/// below what would exhaust memory.
pub const MAX_CASE_BYTES: u64 = 64 * 1024 * 1024;

/// A file of a run directory that cannot be read.
#[derive(Debug, Error)]
pub enum StoreError {
    /// The system refused.
    #[error("cannot read {}", path.display())]
    Read {
        /// The file or directory.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// A case is not a regular file.
    #[error(
        "{}: not a regular file (a directory, FIFO or device): a case is a JSON file",
        path.display()
    )]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
    /// A case file is larger than any case.
    #[error("{}: {bytes} bytes: a case file is at most {MAX_CASE_BYTES} bytes", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
    /// A recording beside the case files is another campaign's.
    #[error(
        "{}: the recording of a campaign with seed {recorded}, campaign.json's is seed {seed}: a \
         recording of another campaign is not read beside this one's cases",
        path.display()
    )]
    OtherCampaign {
        /// The recording.
        path: PathBuf,
        /// The seed its metadata names.
        recorded: String,
        /// The seed of `campaign.json`.
        seed: u64,
    },
    /// A recording's start cannot be read.
    #[error("{}", path.display())]
    Recording {
        /// The recording.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: Box<recording::RecordingError>,
    },
    /// A case file is not a case.
    #[error("{}", path.display())]
    Case {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: Box<CaseError>,
    },
}

/// A run directory and the names of its files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunStore {
    dir: PathBuf,
}

impl RunStore {
    /// The run directory `dir` (nothing is read yet).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// `campaign.json`.
    pub fn campaign(&self) -> PathBuf {
        self.dir.join(CAMPAIGN_FILE)
    }

    /// `campaign.mcap`.
    pub fn recording(&self) -> PathBuf {
        self.dir.join(RECORDING_FILE)
    }

    /// `campaign.mcap.resumed`, the earlier sessions' recording while a resume copies it.
    pub fn prior_recording(&self) -> PathBuf {
        self.dir.join(PRIOR_RECORDING_FILE)
    }

    /// `.drivecheck-writing`, the claim of the process writing the directory.
    pub fn claim(&self) -> PathBuf {
        self.dir.join(CLAIM_FILE)
    }

    /// `.drivecheck-reserve`, the space the writing process keeps back for its session's end.
    pub fn reserve(&self) -> PathBuf {
        self.dir.join(RESERVE_FILE)
    }

    /// Refuses `file`, a recording of this directory (`campaign.mcap`, `campaign.mcap.resumed`),
    /// when it is another campaign's: the seed its `drivecheck.campaign` metadata names (read
    /// from the file's first records) must be `seed`, campaign.json's. Every reader of a
    /// recording beside case files checks this first (resume, report, explain, calibrate).
    pub fn check_recording(&self, file: &Path, seed: u64) -> Result<(), StoreError> {
        let recorded = recording::recorded_seed(file).map_err(|source| StoreError::Recording {
            path: file.to_owned(),
            source: Box::new(source),
        })?;
        match recorded {
            Some(recorded) if recorded != seed.to_string() => Err(StoreError::OtherCampaign {
                path: file.to_owned(),
                recorded,
                seed,
            }),
            _ => Ok(()),
        }
    }

    /// The case file of test `test_index`: `case-NNN.json`.
    pub fn case(&self, test_index: usize) -> PathBuf {
        self.dir.join(case_name(test_index))
    }

    /// The `k`-th kept case of a test cut off and driven again: `case-NNN.partial-K.json`.
    pub fn partial(&self, test_index: usize, k: usize) -> PathBuf {
        self.dir
            .join(format!("case-{test_index:03}.partial-{k}.json"))
    }

    /// The case files (`case-NNN.json`, not the partial cases a resume keeps) with their test
    /// indices, by index (names sort wrong past 999: `case-1000` before `case-999`).
    pub fn case_files(&self) -> Result<Vec<(usize, PathBuf)>, StoreError> {
        let entries = std::fs::read_dir(&self.dir).map_err(|source| StoreError::Read {
            path: self.dir.clone(),
            source,
        })?;
        let mut files: Vec<(usize, PathBuf)> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter_map(|path| Some((case_index(&path)?, path)))
            .collect();
        files.sort();
        Ok(files)
    }

    /// The case file `path`, read whole: a regular file of at most [`MAX_CASE_BYTES`].
    pub fn read_case(path: &Path) -> Result<Case, StoreError> {
        let read = |source| StoreError::Read {
            path: path.to_owned(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(read)?;
        if !meta.is_file() {
            return Err(StoreError::NotAFile {
                path: path.to_owned(),
            });
        }
        if meta.len() > MAX_CASE_BYTES {
            return Err(StoreError::TooLarge {
                path: path.to_owned(),
                bytes: meta.len(),
            });
        }
        let text = std::fs::read_to_string(path).map_err(read)?;
        Case::from_json(&text).map_err(|source| StoreError::Case {
            path: path.to_owned(),
            source: Box::new(source),
        })
    }
}

/// `case-NNN.json` for test `test_index`.
pub fn case_name(test_index: usize) -> String {
    format!("case-{test_index:03}.json")
}

/// The test index of a case file's name (`case-007.json`: 7); `None` for any other file, a
/// partial case (`case-007.partial-1.json`) among them.
pub fn case_index(path: &Path) -> Option<usize> {
    path.file_name()?
        .to_str()?
        .strip_prefix("case-")?
        .strip_suffix(".json")?
        .parse()
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_files_are_listed_by_index_without_partials() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "case-999.json",
            "case-1000.json",
            "case-002.json",
            "case-002.partial-1.json",
            "campaign.json",
            "case-x.json",
        ] {
            std::fs::write(dir.path().join(name), "{}").unwrap();
        }
        let store = RunStore::new(dir.path());
        let listed: Vec<usize> = store
            .case_files()
            .unwrap()
            .into_iter()
            .map(|(i, _)| i)
            .collect();
        assert_eq!(listed, [2, 999, 1000]);
        assert_eq!(store.case(7), dir.path().join("case-007.json"));
        assert_eq!(
            store.partial(7, 2),
            dir.path().join("case-007.partial-2.json")
        );
    }

    #[test]
    fn a_case_that_is_not_a_regular_file_or_too_large_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let error = RunStore::read_case(dir.path()).unwrap_err();
        assert!(matches!(error, StoreError::NotAFile { .. }), "{error}");
        let big = dir.path().join("case-000.json");
        let file = std::fs::File::create(&big).unwrap();
        file.set_len(MAX_CASE_BYTES + 1).unwrap();
        let error = RunStore::read_case(&big).unwrap_err();
        assert!(error.to_string().contains("case-000.json"), "{error}");
        assert!(matches!(error, StoreError::TooLarge { .. }), "{error}");
    }
}
