//! Files written whole or not at all: a temporary file beside the target, flushed to disk, then
//! renamed over it. A full disk, a kill or a crash leaves the old file (or none), never a
//! truncated one, and no temporary file is left behind by an error; the temporary file is this
//! process's scratch ([`crate::scratch`]: a signal removes it, and one a `kill -9` left is removed
//! by the next writer into its directory).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::scratch::Scratch;

/// Writes `contents` to `path` atomically (see the module doc).
pub fn write(path: &Path, contents: impl AsRef<[u8]>) -> std::io::Result<()> {
    let temporary = temporary_beside(path);
    let (scratch, mut file) = Scratch::create(&temporary, |p| std::fs::File::create(p))?;
    let result = (|| {
        file.write_all(contents.as_ref())?;
        file.sync_all()
    })();
    drop(file);
    scratch.settle(|| {
        let result = result.and_then(|()| std::fs::rename(&temporary, path));
        if result.is_err() {
            let _ = std::fs::remove_file(&temporary);
        }
        result
    })
}

/// A file written piece by piece and then put in place whole ([`Staged::commit`]): until then
/// its contents are in a temporary file beside it, which an error or a drop removes.
#[derive(Debug)]
pub struct Staged {
    file: Option<std::io::BufWriter<std::fs::File>>,
    temporary: PathBuf,
    path: PathBuf,
    scratch: Option<Scratch>,
}

impl Staged {
    /// Starts writing `path` (nothing is at `path` until [`Staged::commit`]).
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let temporary = temporary_beside(path);
        let (scratch, file) = Scratch::create(&temporary, |p| std::fs::File::create(p))?;
        Ok(Self {
            file: Some(std::io::BufWriter::with_capacity(1 << 16, file)),
            temporary,
            path: path.to_owned(),
            scratch: Some(scratch),
        })
    }

    /// Flushes the contents to disk and renames them over the target.
    pub fn commit(mut self) -> std::io::Result<()> {
        let Some(file) = self.file.take() else {
            return Ok(());
        };
        let written = (|| {
            let file = file.into_inner().map_err(|e| e.into_error())?;
            file.sync_all()
        })();
        let settle = || {
            let result = written.and_then(|()| std::fs::rename(&self.temporary, &self.path));
            if result.is_err() {
                let _ = std::fs::remove_file(&self.temporary);
            }
            result
        };
        match self.scratch.take() {
            Some(scratch) => scratch.settle(settle),
            None => settle(),
        }
    }
}

impl Write for Staged {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.file {
            Some(file) => file.write(buf),
            None => Err(std::io::Error::other("the file was committed")),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.file {
            Some(file) => file.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}

/// `.<name>.tmp-<pid>` in the same directory (a rename within one file system is atomic).
fn temporary_beside(path: &Path) -> PathBuf {
    crate::scratch::beside(path, "tmp")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_file_is_replaced_whole_and_no_temporary_file_is_left() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("campaign.json");
        write(&file, "old").unwrap();
        write(&file, "new contents").unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "new contents");
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["campaign.json"]);
    }

    #[test]
    fn a_staged_file_appears_whole_on_commit_and_not_at_all_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("report.html");
        let mut staged = Staged::create(&file).unwrap();
        staged.write_all(b"<html>").unwrap();
        assert!(!file.exists(), "nothing is in place before the commit");
        staged.write_all(b"</html>").unwrap();
        staged.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "<html></html>");
        let mut dropped = Staged::create(&file).unwrap();
        dropped.write_all(b"half a page").unwrap();
        drop(dropped);
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "<html></html>");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("case-000.json");
        write(&file, "old").unwrap();
        // The target is a directory now: the rename fails after the temporary file was written.
        let blocked = dir.path().join("blocked");
        std::fs::create_dir(&blocked).unwrap();
        std::fs::write(blocked.join("x"), "x").unwrap();
        assert!(write(&blocked, "new").is_err());
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "old");
        let leftovers = std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .contains(".tmp-")
            })
            .count();
        assert_eq!(leftovers, 0);
    }
}
