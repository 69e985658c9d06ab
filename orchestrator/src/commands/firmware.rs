//! `--car sitl:TREE`: the car's own firmware, built from the user's tree for the host (`sitl`)
//! and driven like the embedded simulated car, a fresh start of it per test
//! (`docs/sitl.md#in-a-campaign`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use car_link::FirmwareVersion;
pub use runner::vehicle::sitl::HostFirmware;

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

/// Builds `tree` (or takes it from the cache) and says so unless quiet.
pub fn build(tree: &str) -> Result<HostFirmware> {
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
    let config = runner::vehicle::sitl::boot_config(&build.executable, version)
        .with_context(|| format!("--car sitl:{tree}: cannot read the firmware's configuration"))?;
    if let Some(differs) = runner::vehicle::sitl::geometry_differences(&config, version) {
        crate::output::note(format_args!(
            "its configuration gives the simulated car another geometry than {version}'s defaults: {differs}"
        ));
    }
    Ok(HostFirmware {
        executable: build.executable,
        version,
        tree_hash: build.tree_hash,
        config,
    })
}

/// The simulated car a command that drives cases on fresh cars is given (`--car`): `sim`, the
/// embedded simulated car (`None`), or `sitl:TREE`, the car's own firmware built for the host
/// (built or taken from the cache). A car behind a link is refused, naming the command
/// ([`crate::settings::DrivenOn`]).
pub fn fresh_car(command: &str, car: &str) -> Result<Option<HostFirmware>> {
    match crate::settings::DrivenOn::resolve(command, car, false, false)? {
        crate::settings::DrivenOn::Firmware(tree) => build(&tree).map(Some),
        _ => Ok(None),
    }
}

/// `drivecheck sitl build TREE`: builds the tree (or takes it from the cache) and says what went
/// into it.
pub fn build_command(args: &crate::cli::SitlBuildArgs) -> Result<crate::exit::Exit> {
    let started = Instant::now();
    let build = sitl::build(&args.tree, &cache_dir()).with_context(|| {
        format!(
            "{}: cannot build the firmware for the host",
            args.tree.display()
        )
    })?;
    let seconds = started.elapsed().as_secs_f64();
    let version = FirmwareVersion::new(build.version.0, build.version.1);
    if args.json {
        #[derive(serde::Serialize)]
        struct Built<'a> {
            tree: &'a Path,
            firmware: String,
            tree_hash: &'a str,
            executable: &'a Path,
            cached: bool,
            seconds: f64,
            compiled: &'a [String],
            stubbed: &'a [String],
        }
        crate::output::print_json(
            crate::output::json::SITL_BUILD,
            &Built {
                tree: &args.tree,
                firmware: version.to_string(),
                tree_hash: &build.tree_hash,
                executable: &build.executable,
                cached: build.cached,
                seconds,
                compiled: &build.compiled,
                stubbed: &build.stubbed,
            },
        )?;
    } else {
        println!(
            "firmware {version} of {} built for the host ({})",
            args.tree.display(),
            if build.cached {
                "from the cache".to_owned()
            } else {
                format!("in {seconds:.1} s")
            }
        );
        println!("  tree hash  {}", build.tree_hash);
        println!("  executable {}", build.executable.display());
        println!(
            "  compiled   {} files: {}",
            build.compiled.len(),
            build.compiled.join(", ")
        );
        println!(
            "  stubbed    {} symbols the shim provides: {}",
            build.stubbed.len(),
            build.stubbed.join(", ")
        );
    }
    Ok(crate::exit::Exit::Success)
}
