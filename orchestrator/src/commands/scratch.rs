//! Scratch directories of this process, removed when dropped.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// A scratch directory of this process (`drivecheck-<kind>-<pid>-<name>` in the system's
/// temporary directory), removed when dropped: for runs whose case files are read from the
/// report, not from disk.
pub struct Scratch(pub PathBuf);

impl Scratch {
    /// Where a bench puts its run directories: `given` (`--scratch DIR`, created new and kept),
    /// else a scratch directory removed when the returned guard is dropped.
    pub fn given_or_new(
        given: Option<&Path>,
        kind: &str,
        name: &str,
    ) -> Result<(Option<Self>, PathBuf)> {
        match given {
            Some(dir) => {
                std::fs::create_dir(dir)
                    .with_context(|| format!("--scratch {}: cannot create it", dir.display()))?;
                Ok((None, dir.to_owned()))
            }
            None => {
                let scratch = Self::new(kind, name)?;
                let root = scratch.0.clone();
                Ok((Some(scratch), root))
            }
        }
    }

    /// A new, empty scratch directory `drivecheck-<kind>-<pid>-<name>` (one left by an earlier
    /// process of the same pid is removed first).
    pub fn new(kind: &str, name: &str) -> Result<Self> {
        let path =
            std::env::temp_dir().join(format!("drivecheck-{kind}-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        Ok(Self(path))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
