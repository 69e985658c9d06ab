//! `--car sitl:TREE`: the car's own firmware, built from the user's tree for the host (`sitl`)
//! and driven like the embedded simulated car, a fresh start of it per test
//! (`docs/sitl.md#in-a-campaign`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use car_link::FirmwareVersion;

/// The environment variable that overrides where built firmware executables are kept.
pub const CACHE_ENV: &str = "DRIVECHECK_SITL_CACHE";

/// Where built executables are kept: `$DRIVECHECK_SITL_CACHE`, else `$XDG_CACHE_HOME/drivecheck/sitl`,
/// else `~/.cache/drivecheck/sitl`, else `.drivecheck-sitl` here. (They contain firmware code:
/// never in a run directory or a repository.)
pub fn cache_dir() -> PathBuf {
    let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty());
    if let Some(dir) = var(CACHE_ENV) {
        return PathBuf::from(dir);
    }
    if let Some(dir) = var("XDG_CACHE_HOME") {
        return PathBuf::from(dir).join("drivecheck").join("sitl");
    }
    if let Some(home) = var("HOME") {
        return PathBuf::from(home)
            .join(".cache")
            .join("drivecheck")
            .join("sitl");
    }
    PathBuf::from(".drivecheck-sitl")
}

/// A firmware tree built for the host: the executable and the firmware version it reports.
#[derive(Debug, Clone)]
pub struct BuiltFirmware {
    /// The executable.
    pub executable: PathBuf,
    /// The tree's firmware version.
    pub version: FirmwareVersion,
}

/// Builds `tree` (or takes it from the cache) and says so unless quiet.
pub fn build(tree: &str) -> Result<BuiltFirmware> {
    let started = Instant::now();
    let cache = cache_dir();
    let build = sitl::build(Path::new(tree), &cache)
        .with_context(|| format!("--car sitl:{tree}: cannot build the firmware for the host"))?;
    let version = FirmwareVersion::new(build.version.0, build.version.1);
    crate::output::note(format_args!(
        "firmware {version} of {tree} built for the host ({}, {} files; {})",
        if build.cached {
            "from the cache".to_string()
        } else {
            format!("in {:.1} s", started.elapsed().as_secs_f64())
        },
        build.compiled.len(),
        build.executable.display()
    ));
    Ok(BuiltFirmware {
        executable: build.executable,
        version,
    })
}
