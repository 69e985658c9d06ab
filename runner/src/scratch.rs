//! This process's scratch files: what it writes beside a file before putting it in place
//! (`.NAME.tmp-PID`, [`crate::atomic`]), the report's sections (`.NAME.sections-PID`), a merge's
//! staging directory (`.NAME.staging-PID`), a command's scratch run directories. Each is
//! registered while it exists ([`Scratch`]), so that a command ended by a signal removes them
//! before it exits ([`remove_all`], which the command line's signal handling calls); what a process
//! killed without a chance (`kill -9`, a crash, a power cut) left is removed by the next process
//! that writes into the directory ([`clear_leftovers`], [`clear_leftovers_of`]): a scratch file is
//! named after its process, and one whose process no longer runs is nobody's.
//!
//! Creating a scratch file and putting it in place (its rename) happen while the registry is
//! held, and [`remove_all`] holds it until the process ends: a signal never leaves a scratch file
//! that was created after the removal, nor removes a file that was already in place.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// The kinds of scratch file, as their names end: `.NAME.KIND-PID`.
pub const KINDS: [&str; 3] = ["tmp", "sections", "staging"];

/// The registry: every scratch path of this process that exists now.
#[derive(Debug, Default)]
pub struct Registry {
    next: u64,
    paths: BTreeMap<u64, PathBuf>,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    next: 0,
    paths: BTreeMap::new(),
});

fn registry() -> MutexGuard<'static, Registry> {
    REGISTRY.lock().unwrap_or_else(PoisonError::into_inner)
}

/// `.NAME.KIND-PID` beside `path` (`NAME` its file name, `PID` this process's).
pub fn beside(path: &Path, kind: &str) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{kind}-{}", std::process::id()))
}

/// A registered scratch path (see the module doc); dropping it forgets the path (its owner
/// removes the file, or has put it in place).
#[derive(Debug)]
pub struct Scratch {
    id: u64,
}

impl Scratch {
    /// Registers `path` and creates it with `make`, while no signal removes the scratch: the
    /// path is registered only when `make` succeeds.
    pub fn create<T>(
        path: &Path,
        make: impl FnOnce(&Path) -> std::io::Result<T>,
    ) -> std::io::Result<(Self, T)> {
        let mut registry = registry();
        let made = make(path)?;
        let id = registry.next;
        registry.next += 1;
        registry.paths.insert(id, path.to_owned());
        Ok((Self { id }, made))
    }

    /// Makes a scratch path with `make`, which chooses its name (a staging directory: the first
    /// free one), and registers it, while no signal removes the scratch.
    pub fn create_named(
        make: impl FnOnce() -> std::io::Result<PathBuf>,
    ) -> std::io::Result<(Self, PathBuf)> {
        let mut registry = registry();
        let path = make()?;
        let id = registry.next;
        registry.next += 1;
        registry.paths.insert(id, path.clone());
        Ok((Self { id }, path))
    }

    /// Registers `path`, which this process is about to create (a scratch directory made by
    /// another function) or just made.
    pub fn register(path: &Path) -> Self {
        let mut registry = registry();
        let id = registry.next;
        registry.next += 1;
        registry.paths.insert(id, path.to_owned());
        Self { id }
    }

    /// Runs `settle` (the rename into place, or the removal) and forgets the path, while no
    /// signal removes the scratch.
    pub fn settle<T>(self, settle: impl FnOnce() -> T) -> T {
        let mut registry = registry();
        let settled = settle();
        registry.paths.remove(&self.id);
        drop(registry);
        std::mem::forget(self);
        settled
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        registry().paths.remove(&self.id);
    }
}

/// The registry, held until the process ends: see [`remove_all`].
#[derive(Debug)]
pub struct Held(#[allow(dead_code)] MutexGuard<'static, Registry>);

/// Removes every scratch path of this process (files, and directories with what is in them) and
/// holds the registry from then on, so that no scratch is created or put in place before the
/// process ends: call it right before ending the process (a signal), and keep what it returns.
pub fn remove_all() -> Held {
    let registry = registry();
    remove_registered(&registry, |_| true);
    Held(registry)
}

/// Removes the registered paths `within` says.
fn remove_registered(registry: &Registry, within: impl Fn(&Path) -> bool) {
    for path in registry.paths.values().filter(|p| within(p)) {
        remove(path);
    }
}

/// Removes `path`, a file (a symbolic link itself, not what it names) or a directory; best
/// effort.
fn remove(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.is_dir() => {
            // A writer may add a file while the tree is removed: try again.
            for _ in 0..3 {
                if std::fs::remove_dir_all(path).is_ok() || !path.exists() {
                    break;
                }
            }
        }
        Ok(_) => {
            let _ = std::fs::remove_file(path);
        }
        Err(_) => {}
    }
}

/// A scratch file of a process that no longer runs, removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Leftover {
    /// Where it was.
    pub path: PathBuf,
    /// The process that wrote it.
    pub pid: u32,
}

/// Whether process `pid` runs on this system; `None` when that cannot be told (no `/proc`).
pub fn process_alive(pid: u32) -> Option<bool> {
    let proc = Path::new("/proc");
    proc.is_dir()
        .then(|| pid == std::process::id() || proc.join(pid.to_string()).exists())
}

/// The process of a scratch file's name (`.NAME.KIND-PID`, a staging directory's also
/// `.NAME.staging-PID-N`) and the `NAME` it is the scratch of; `None` for any other name.
pub fn scratch_of(file_name: &str) -> Option<(&str, u32)> {
    let rest = file_name.strip_prefix('.')?;
    let (name, tail) = rest.rsplit_once('.').filter(|(_, tail)| {
        KINDS
            .iter()
            .any(|kind| tail.strip_prefix(kind).is_some_and(|t| t.starts_with('-')))
    })?;
    let (_, pid) = tail.split_once('-')?;
    let pid = pid.split('-').next()?;
    if name.is_empty() || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((name, pid.parse().ok()?))
}

/// Removes the scratch files in `dir` whose process no longer runs (every name of [`KINDS`]: call
/// it on a directory only drivecheck writes, a run directory); what it removed. Nothing is
/// removed where processes cannot be told apart (no `/proc`).
pub fn clear_leftovers(dir: &Path) -> Vec<Leftover> {
    clear(dir, |_| true)
}

/// Removes the scratch files of `path` (`.NAME.KIND-PID` beside it, `NAME` its file name) whose
/// process no longer runs; what it removed.
pub fn clear_leftovers_of(path: &Path) -> Vec<Leftover> {
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return Vec::new();
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    clear(dir, |of| of == name)
}

fn clear(dir: &Path, of: impl Fn(&str) -> bool) -> Vec<Leftover> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for entry in entries.filter_map(Result::ok) {
        let file_name = entry.file_name();
        let Some((name, pid)) = file_name.to_str().and_then(scratch_of) else {
            continue;
        };
        if !of(name) || process_alive(pid) != Some(false) {
            continue;
        }
        let path = entry.path();
        remove(&path);
        if std::fs::symlink_metadata(&path).is_err() {
            removed.push(Leftover { path, pid });
        }
    }
    removed.sort_by(|a, b| a.path.cmp(&b.path));
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pid above any `pid_max` (4194304) is no process.
    const DEAD: u32 = 4_294_967_295;

    #[test]
    fn scratch_names_are_read_and_others_are_not() {
        assert_eq!(
            scratch_of(".case-003.json.tmp-42"),
            Some(("case-003.json", 42))
        );
        assert_eq!(
            scratch_of(".report.html.sections-7"),
            Some(("report.html", 7))
        );
        assert_eq!(scratch_of(".merged.staging-9-2"), Some(("merged", 9)));
        for other in [
            "case-003.json",
            ".drivecheck-writing",
            ".case.json.tmp-",
            ".case.json.tmp-12x",
            ".tmp-12",
            "x.tmp-12",
            ".case.json.backup-12",
        ] {
            assert_eq!(scratch_of(other), None, "{other}");
        }
    }

    #[test]
    fn a_dead_processs_scratch_is_removed_and_a_live_ones_and_other_files_are_not() {
        if process_alive(1).is_none() {
            return; // no /proc: nothing is ever removed
        }
        let dir = tempfile::tempdir().unwrap();
        let me = std::process::id();
        let names = [
            format!(".case-003.json.tmp-{DEAD}"),
            format!(".report.html.sections-{DEAD}"),
            format!(".case-004.json.tmp-{me}"),
            "case-003.json".to_owned(),
            format!("notes.tmp-{DEAD}"),
        ];
        for name in &names {
            std::fs::write(dir.path().join(name), "x").unwrap();
        }
        let staging = dir.path().join(format!(".merged.staging-{DEAD}"));
        std::fs::create_dir(&staging).unwrap();
        std::fs::write(staging.join("campaign.json"), "{}").unwrap();
        // Only the report's own scratch.
        let of_report = clear_leftovers_of(&dir.path().join("report.html"));
        assert_eq!(
            of_report,
            [Leftover {
                path: dir.path().join(&names[1]),
                pid: DEAD
            }]
        );
        let removed: Vec<PathBuf> = clear_leftovers(dir.path())
            .into_iter()
            .map(|l| l.path)
            .collect();
        assert_eq!(removed, [dir.path().join(&names[0]), staging.clone()]);
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        let mut kept = vec![names[2].clone(), names[3].clone(), names[4].clone()];
        kept.sort();
        assert_eq!(left, kept);
    }

    #[test]
    fn remove_all_removes_what_is_registered_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join(".a.tmp-1");
        let (scratch, ()) = Scratch::create(&file, |p| std::fs::write(p, "half")).expect("created");
        let tree = dir.path().join(".b.staging-1");
        let tree_scratch = Scratch::register(&tree);
        std::fs::create_dir(&tree).unwrap();
        std::fs::write(tree.join("case-000.json"), "{}").unwrap();
        let settled = dir.path().join(".c.tmp-1");
        let (put, ()) = Scratch::create(&settled, |p| std::fs::write(p, "whole")).unwrap();
        let target = dir.path().join("c");
        put.settle(|| std::fs::rename(&settled, &target)).unwrap();
        // As `remove_all` does, of this test's paths only (other tests write files meanwhile).
        let held = registry();
        remove_registered(&held, |p| p.starts_with(dir.path()));
        assert!(!file.exists() && !tree.exists());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "whole");
        let ours = |r: &Registry| {
            r.paths
                .values()
                .filter(|p| p.starts_with(dir.path()))
                .count()
        };
        assert_eq!(ours(&held), 2, "the settled file is forgotten");
        drop(held);
        drop((scratch, tree_scratch));
        assert_eq!(ours(&registry()), 0);
    }
}
