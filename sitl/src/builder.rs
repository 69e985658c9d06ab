//! Building a firmware tree for the host: the portable sources, drivecheck's shim, the system C
//! compiler, and a cache keyed by what went in.

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use sha2::{Digest, Sha256};
use thiserror::Error;

/// The firmware's portable C modules, as `(file, required)`: what compiles for the host
/// unmodified. Each is looked for in the tree's top folder, then in `imu/` (where 12.x keeps
/// `ahrs.c`). A tree without a required one is refused; optional ones are compiled when present.
pub const PORTABLE_SOURCES: &[(&str, bool)] = &[
    ("pos.c", true),
    ("pos_uwb.c", true),
    ("fi.c", true),
    ("autopilot.c", true),
    ("commands.c", true),
    ("packet.c", true),
    ("terminal.c", true),
    ("utils.c", true),
    ("buffer.c", true),
    ("crc.c", true),
    ("ahrs.c", true),
    ("bldc_interface.c", true),
    ("conf_general.c", true),
    ("timeout.c", true),
    ("motor_sim.c", true),
    ("rtcm3_simple.c", true),
    ("digital_filter.c", false),
];

/// Folders of the tree searched for sources, and for headers after the shim's own.
const TREE_DIRS: &[&str] = &["", "imu"];
/// Header-only folders of the tree added to the include path when present (a radio driver's
/// declarations that `terminal.c` includes; the IMU driver's for `pos.c`). Never ChibiOS's.
pub(crate) const TREE_INCLUDE_DIRS: &[&str] = &["", "imu", "imu/BMI160_driver", "cc1120"];

/// buffer.c's scaled float appenders, reached through `ld --wrap` so that other modules' calls
/// convert to integers as the Cortex-M4 does (saturating; NaN gives 0), see `sitl_fw.c`.
const WRAPPED: &[&str] = &["buffer_append_float32", "buffer_append_float16"];

macro_rules! shim_file {
    ($p:literal) => {
        ($p, include_str!(concat!("../shim/", $p)))
    };
}

/// drivecheck's shim, embedded so that a build works from an installed binary.
const SHIM: &[(&str, &str)] = &[
    shim_file!("include/ch.h"),
    shim_file!("include/chtypes.h"),
    shim_file!("include/chsystypes.h"),
    shim_file!("include/hal.h"),
    shim_file!("include/stm32f4xx_conf.h"),
    shim_file!("include/eeprom.h"),
    shim_file!("include/chprintf.h"),
    shim_file!("src/sitl.h"),
    shim_file!("src/sitl_rt.c"),
    shim_file!("src/sitl_hal.c"),
    shim_file!("src/sitl_hw.c"),
    shim_file!("src/sitl_fw.c"),
    shim_file!("src/sitl_io.c"),
];

/// The shim's files, as `(path under sitl/shim, contents)`.
pub fn shim_sources() -> &'static [(&'static str, &'static str)] {
    SHIM
}

const C_FLAGS: &[&str] = &[
    "-std=gnu99",
    "-O2",
    "-fsingle-precision-constant",
    "-DMAIN_MODE=0",
];
const LINK_FLAGS: &[&str] = &["-lm"];
const EXECUTABLE: &str = "sitl-firmware";
const MANIFEST: &str = "manifest.txt";
const CACHE_FORMAT: &str = "drivecheck-sitl-cache 1";

/// A built firmware executable.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Build {
    /// The executable (in the cache).
    pub executable: PathBuf,
    /// `FW_VERSION_MAJOR`, `FW_VERSION_MINOR` from the tree's `conf_general.h`.
    pub version: (u8, u8),
    /// SHA-256 (hex) of the tree's files that went into the build: the compiled sources, the
    /// headers of the folders on the include path and `main.c`.
    pub tree_hash: String,
    /// The compiled firmware sources, relative to the tree (`imu/ahrs.c`).
    pub compiled: Vec<String>,
    /// The symbols the firmware's objects need that the shim provides, sorted (from `nm`).
    pub stubbed: Vec<String>,
    /// Whether the executable came from the cache.
    pub cached: bool,
}

/// Why a tree did not build.
#[derive(Debug, Error)]
pub enum BuildError {
    /// The path is not a firmware tree.
    #[error("{}: not a firmware tree ({reason})", path.display())]
    NotATree {
        /// The tree.
        path: PathBuf,
        /// What is missing.
        reason: String,
    },
    /// `conf_general.h` has no firmware version.
    #[error("{}: no `#define FW_VERSION_MAJOR`/`FW_VERSION_MINOR` with a number", path.display())]
    NoVersion {
        /// The header.
        path: PathBuf,
    },
    /// A required portable source is missing.
    #[error("{}: missing the portable source {name}", tree.display())]
    MissingSource {
        /// The tree.
        tree: PathBuf,
        /// The file.
        name: String,
    },
    /// The C compiler (or `nm`) could not be run.
    #[error("cannot run `{tool}`: {source}")]
    Tool {
        /// The command.
        tool: String,
        /// Why.
        source: std::io::Error,
    },
    /// A source did not compile.
    #[error("{file}: {first_error}")]
    Compile {
        /// The source: tree-relative for the firmware's, `shim/...` for the shim's.
        file: String,
        /// The compiler's first error line.
        first_error: String,
        /// Everything the compiler said.
        stderr: String,
    },
    /// The link found symbols nothing defines.
    #[error("link: undefined reference to `{symbol}`{}{}",
        file.as_ref().map(|f| format!(" (from {f})")).unwrap_or_default(),
        if others.is_empty() { String::new() } else { format!(", and {} more: {}", others.len(), others.join(", ")) })]
    Undefined {
        /// The first missing symbol.
        symbol: String,
        /// The source whose object needs it, when the linker says.
        file: Option<String>,
        /// The other missing symbols.
        others: Vec<String>,
    },
    /// The link failed otherwise.
    #[error("link: {first_error}")]
    Link {
        /// The linker's first error line.
        first_error: String,
        /// Everything it said.
        stderr: String,
    },
    /// `nm` failed on an object.
    #[error("nm {}: {message}", object.display())]
    Nm {
        /// The object.
        object: PathBuf,
        /// What it said.
        message: String,
    },
    /// Reading the tree or writing the cache failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> BuildError + '_ {
    move |source| BuildError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reads `FW_VERSION_MAJOR` and `FW_VERSION_MINOR` from a `conf_general.h` text.
pub(crate) fn parse_version(text: &str) -> Option<(u8, u8)> {
    let find = |name: &str| {
        text.lines().find_map(|line| {
            let mut words = line.split_whitespace();
            (words.next() == Some("#define") && words.next() == Some(name))
                .then(|| words.next().and_then(|v| v.parse::<u8>().ok()))
                .flatten()
        })
    };
    Some((find("FW_VERSION_MAJOR")?, find("FW_VERSION_MINOR")?))
}

/// What the tree's `main.c` configures that the shim's start-up reproduces: the arguments of
/// `timeout_configure(ms, brake_current)` and the main loop's sleep before `packet_timerfunc()`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MainParams {
    pub timeout_ms: u32,
    pub timeout_brake: f64,
    pub loop_ms: u32,
}

impl Default for MainParams {
    fn default() -> Self {
        MainParams {
            timeout_ms: 2000,
            timeout_brake: 20.0,
            loop_ms: 2,
        }
    }
}

fn call_args<'a>(text: &'a str, name: &str) -> Option<&'a str> {
    let start = text.find(name)? + name.len();
    let rest = text[start..].trim_start().strip_prefix('(')?;
    Some(&rest[..rest.find(')')?])
}

pub(crate) fn parse_main(text: &str) -> MainParams {
    let mut p = MainParams::default();
    if let Some(args) = call_args(text, "timeout_configure") {
        let mut it = args.split(',').map(str::trim);
        if let (Some(Ok(ms)), Some(Ok(brake))) = (
            it.next().map(str::parse::<u32>),
            it.next()
                .map(|b| b.trim_end_matches(['f', 'F']).parse::<f64>()),
        ) {
            p.timeout_ms = ms;
            p.timeout_brake = brake;
        }
    }
    if let Some(at) = text.find("packet_timerfunc()")
        && let Some(sleep) = text[..at].rfind("chThdSleepMilliseconds")
        && let Some(ms) = call_args(&text[sleep..at], "chThdSleepMilliseconds")
            .and_then(|a| a.trim().parse().ok())
    {
        p.loop_ms = ms;
    }
    p
}

/// Whether an `mpu9150.h` declares the 10.x read callback without arguments.
pub(crate) fn imu_callback_without_args(header: &str) -> bool {
    let squeezed: String = header.chars().filter(|c| !c.is_whitespace()).collect();
    squeezed.contains("mpu9150_set_read_callback(void(*func)(void))")
}

/// The first line of a compiler's or linker's output that reports an error.
pub(crate) fn first_error_line(stderr: &str) -> String {
    stderr
        .lines()
        .find(|l| l.contains("error:") || l.contains("error "))
        .or_else(|| stderr.lines().find(|l| !l.trim().is_empty()))
        .unwrap_or("failed without a message")
        .trim()
        .to_string()
}

/// Missing symbols in a GNU ld (or lld) error output, with the object that needs the first.
pub(crate) fn parse_undefined(stderr: &str) -> Vec<(String, Option<String>)> {
    let mut found: Vec<(String, Option<String>)> = Vec::new();
    let mut object: Option<String> = None;
    for line in stderr.lines() {
        if let Some(pos) = line.find(".o:") {
            let before = &line[..pos + 2];
            let name = before.rsplit(['/', ' ']).next().unwrap_or(before);
            object = Some(name.to_string());
        }
        let symbol = if let Some(i) = line.find("undefined reference to `") {
            let s = &line[i + "undefined reference to `".len()..];
            s.find('\'').map(|e| s[..e].to_string())
        } else {
            line.find("undefined symbol: ")
                .map(|i| line[i + "undefined symbol: ".len()..].trim().to_string())
        };
        if let Some(symbol) = symbol
            && !found.iter().any(|(s, _)| *s == symbol)
        {
            found.push((symbol, object.clone()));
        }
    }
    found
}

/// Defined and undefined global symbols in `nm` output.
pub(crate) fn parse_nm(text: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let (mut defined, mut undefined) = (BTreeSet::new(), BTreeSet::new());
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.as_slice() {
            ["U", name] => {
                undefined.insert((*name).to_string());
            }
            [_, kind, name] if kind.chars().all(|c| c.is_ascii_uppercase()) && *kind != "U" => {
                defined.insert((*name).to_string());
            }
            _ => {}
        }
    }
    (defined, undefined)
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .fold(String::with_capacity(bytes.len() * 2), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}

fn tool_command(var: &str, default: &str) -> (OsString, Vec<OsString>) {
    let value = std::env::var_os(var)
        .filter(|v| !v.is_empty())
        .unwrap_or_else(|| default.into());
    let text = value.to_string_lossy().into_owned();
    let mut words = text.split_whitespace().map(OsString::from);
    let program = words.next().unwrap_or_else(|| default.into());
    (program, words.collect())
}

fn command(tool: &(OsString, Vec<OsString>)) -> Command {
    let mut c = Command::new(&tool.0);
    c.args(&tool.1);
    c
}

fn tool_name(tool: &(OsString, Vec<OsString>)) -> String {
    let mut s = tool.0.to_string_lossy().into_owned();
    for a in &tool.1 {
        s.push(' ');
        s.push_str(&a.to_string_lossy());
    }
    s
}

struct Source {
    rel: String,
    path: PathBuf,
}

fn find_sources(tree: &Path) -> Result<Vec<Source>, BuildError> {
    let mut out = Vec::new();
    for (name, required) in PORTABLE_SOURCES {
        let found = TREE_DIRS.iter().find_map(|dir| {
            let rel = if dir.is_empty() {
                (*name).to_string()
            } else {
                format!("{dir}/{name}")
            };
            let path = tree.join(&rel);
            path.is_file().then_some(Source { rel, path })
        });
        match found {
            Some(s) => out.push(s),
            None if *required => {
                return Err(BuildError::MissingSource {
                    tree: tree.to_path_buf(),
                    name: (*name).to_string(),
                });
            }
            None => {}
        }
    }
    Ok(out)
}

/// The tree's hash: the compiled sources, the headers on the include path and `main.c`.
fn tree_hash(tree: &Path, sources: &[Source]) -> Result<String, BuildError> {
    let mut files: BTreeSet<String> = sources.iter().map(|s| s.rel.clone()).collect();
    for dir in TREE_INCLUDE_DIRS {
        let d = tree.join(dir);
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.ends_with(".h") && e.path().is_file() {
                files.insert(if dir.is_empty() {
                    name
                } else {
                    format!("{dir}/{name}")
                });
            }
        }
    }
    if tree.join("main.c").is_file() {
        files.insert("main.c".into());
    }
    let mut h = Sha256::new();
    for rel in &files {
        let p = tree.join(rel);
        let data = std::fs::read(&p).map_err(io_err(&p))?;
        h.update((rel.len() as u64).to_le_bytes());
        h.update(rel.as_bytes());
        h.update((data.len() as u64).to_le_bytes());
        h.update(&data);
    }
    Ok(hex(&h.finalize()))
}

fn read_manifest(dir: &Path) -> Option<Build> {
    let text = std::fs::read_to_string(dir.join(MANIFEST)).ok()?;
    let mut lines = text.lines();
    if lines.next()? != CACHE_FORMAT {
        return None;
    }
    let (mut version, mut tree_hash) = (None, None);
    let (mut compiled, mut stubbed) = (Vec::new(), Vec::new());
    for line in lines {
        let (key, value) = line.split_once(' ')?;
        match key {
            "version" => {
                let (a, b) = value.split_once('.')?;
                version = Some((a.parse().ok()?, b.parse().ok()?));
            }
            "tree" => tree_hash = Some(value.to_string()),
            "compiled" => compiled.push(value.to_string()),
            "stub" => stubbed.push(value.to_string()),
            _ => return None,
        }
    }
    let executable = dir.join(EXECUTABLE);
    executable.is_file().then_some(Build {
        executable,
        version: version?,
        tree_hash: tree_hash?,
        compiled,
        stubbed,
        cached: true,
    })
}

fn write_manifest(dir: &Path, b: &Build) -> Result<(), BuildError> {
    let mut s = format!(
        "{CACHE_FORMAT}\nversion {}.{}\ntree {}\n",
        b.version.0, b.version.1, b.tree_hash
    );
    for c in &b.compiled {
        let _ = writeln!(s, "compiled {c}");
    }
    for c in &b.stubbed {
        let _ = writeln!(s, "stub {c}");
    }
    let p = dir.join(MANIFEST);
    std::fs::write(&p, s).map_err(io_err(&p))
}

struct Job {
    /// The name errors give: tree-relative, or `shim/src/...`.
    label: String,
    source: PathBuf,
    object: PathBuf,
    firmware: bool,
}

fn compile_all(
    cc: &(OsString, Vec<OsString>),
    jobs: &[Job],
    includes: &[PathBuf],
    defines: &[String],
) -> Result<(), BuildError> {
    let next = AtomicUsize::new(0);
    // after a failure, the jobs before it still finish (so the error reported is the first in
    // source order) and the jobs after it are not started
    let failed = AtomicUsize::new(usize::MAX);
    let results: Mutex<Vec<Option<Result<(), BuildError>>>> =
        Mutex::new((0..jobs.len()).map(|_| None).collect());
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, 4);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    if i > failed.load(Ordering::SeqCst) {
                        break;
                    }
                    let Some(job) = jobs.get(i) else { break };
                    let r = compile_one(cc, job, includes, defines);
                    if r.is_err() {
                        failed.fetch_min(i, Ordering::SeqCst);
                    }
                    if let Ok(mut v) = results.lock() {
                        v[i] = Some(r);
                    }
                }
            });
        }
    });
    let results = results.into_inner().unwrap_or_default();
    // the first failure in source order, not in finishing order
    for r in results.into_iter().flatten() {
        r?;
    }
    Ok(())
}

fn compile_one(
    cc: &(OsString, Vec<OsString>),
    job: &Job,
    includes: &[PathBuf],
    defines: &[String],
) -> Result<(), BuildError> {
    let mut c = command(cc);
    c.args(C_FLAGS).args(defines);
    if job.firmware {
        c.arg("-w"); // the firmware's warnings are not ours to fix
    } else {
        c.args(["-Wall", "-Wextra", "-Wno-unused-parameter"]);
    }
    for i in includes {
        c.arg("-I").arg(i);
    }
    c.arg("-c").arg(&job.source).arg("-o").arg(&job.object);
    let out = c.output().map_err(|source| BuildError::Tool {
        tool: tool_name(cc),
        source,
    })?;
    if out.status.success() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    Err(BuildError::Compile {
        file: job.label.clone(),
        first_error: first_error_line(&stderr),
        stderr,
    })
}

fn nm_symbols(
    nm: &(OsString, Vec<OsString>),
    object: &Path,
) -> Result<(BTreeSet<String>, BTreeSet<String>), BuildError> {
    let out = command(nm)
        .arg(object)
        .output()
        .map_err(|source| BuildError::Tool {
            tool: tool_name(nm),
            source,
        })?;
    if !out.status.success() {
        return Err(BuildError::Nm {
            object: object.to_path_buf(),
            message: first_error_line(&String::from_utf8_lossy(&out.stderr)),
        });
    }
    Ok(parse_nm(&String::from_utf8_lossy(&out.stdout)))
}

/// Builds the firmware tree at `tree` (its `Embedded/RC_Controller` folder) for the host, or
/// takes the executable from `cache` when the same tree, shim and compiler built it before.
///
/// The C compiler is `$CC` (default `cc`), `nm` is `$NM` (default `nm`). The tree is only read:
/// its portable sources are copied to a work folder in the cache and compiled there, with the
/// shim's include folder first, so that the tree's own `stm32f4xx_conf.h`, `eeprom.h` and
/// ChibiOS headers never shadow the shim's.
pub fn build(tree: &Path, cache: &Path) -> Result<Build, BuildError> {
    if !tree.is_dir() {
        return Err(BuildError::NotATree {
            path: tree.to_path_buf(),
            reason: "no such folder".into(),
        });
    }
    let conf = tree.join("conf_general.h");
    if !conf.is_file() {
        return Err(BuildError::NotATree {
            path: tree.to_path_buf(),
            reason: "no conf_general.h".into(),
        });
    }
    let conf_text =
        String::from_utf8_lossy(&std::fs::read(&conf).map_err(io_err(&conf))?).into_owned();
    let version =
        parse_version(&conf_text).ok_or_else(|| BuildError::NoVersion { path: conf.clone() })?;
    let sources = find_sources(tree)?;
    let tree_hash = tree_hash(tree, &sources)?;

    let main_params = std::fs::read(tree.join("main.c"))
        .map(|t| parse_main(&String::from_utf8_lossy(&t)))
        .unwrap_or_default();
    let imu_noargs = ["mpu9150.h", "imu/mpu9150.h"]
        .iter()
        .filter_map(|h| std::fs::read(tree.join(h)).ok())
        .any(|t| imu_callback_without_args(&String::from_utf8_lossy(&t)));
    let defines = vec![
        format!("-DSITL_IMU_CB_NOARGS={}", u8::from(imu_noargs)),
        format!("-DSITL_TIMEOUT_MS={}", main_params.timeout_ms),
        format!("-DSITL_TIMEOUT_BRAKE={:?}", main_params.timeout_brake),
        format!("-DSITL_MAIN_LOOP_MS={}", main_params.loop_ms),
    ];

    let cc = tool_command("CC", "cc");
    let nm = tool_command("NM", "nm");
    let cc_version = command(&cc)
        .arg("--version")
        .output()
        .map_err(|source| BuildError::Tool {
            tool: tool_name(&cc),
            source,
        })?;

    let mut key = Sha256::new();
    key.update(CACHE_FORMAT.as_bytes());
    key.update(tree_hash.as_bytes());
    for (name, text) in SHIM {
        key.update(name.as_bytes());
        key.update((text.len() as u64).to_le_bytes());
        key.update(text.as_bytes());
    }
    key.update(tool_name(&cc).as_bytes());
    key.update(&cc_version.stdout);
    // everything on the compiler's and the linker's command lines
    for f in C_FLAGS
        .iter()
        .copied()
        .chain(defines.iter().map(String::as_str))
        .chain(WRAPPED.iter().copied())
        .chain(LINK_FLAGS.iter().copied())
    {
        key.update(f.as_bytes());
        key.update([0]);
    }
    let key = hex(&key.finalize())[..32].to_string();

    let final_dir = cache.join(&key);
    if let Some(b) = read_manifest(&final_dir) {
        return Ok(b);
    }

    std::fs::create_dir_all(cache).map_err(io_err(cache))?;
    // unique per build, also between threads of one process
    static BUILDS: AtomicUsize = AtomicUsize::new(0);
    let work = cache.join(format!(
        ".work-{key}-{}-{}",
        std::process::id(),
        BUILDS.fetch_add(1, Ordering::SeqCst)
    ));
    let _ = std::fs::remove_dir_all(&work);
    let result = build_in(
        tree, &work, &sources, &defines, &cc, &nm, version, &tree_hash,
    );
    let mut b = match result {
        Ok(b) => b,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&work);
            return Err(e);
        }
    };
    // keep only the executable and the manifest
    for d in ["src", "obj", "shim"] {
        let _ = std::fs::remove_dir_all(work.join(d));
    }
    write_manifest(&work, &b)?;
    match std::fs::rename(&work, &final_dir) {
        Ok(()) => {}
        Err(_) if read_manifest(&final_dir).is_some() => {
            // another build of the same key finished first
            let _ = std::fs::remove_dir_all(&work);
        }
        Err(source) => {
            return Err(BuildError::Io {
                path: final_dir,
                source,
            });
        }
    }
    b.executable = final_dir.join(EXECUTABLE);
    Ok(b)
}

#[allow(clippy::too_many_arguments)]
fn build_in(
    tree: &Path,
    work: &Path,
    sources: &[Source],
    defines: &[String],
    cc: &(OsString, Vec<OsString>),
    nm: &(OsString, Vec<OsString>),
    version: (u8, u8),
    tree_hash: &str,
) -> Result<Build, BuildError> {
    let (src, obj, shim) = (work.join("src"), work.join("obj"), work.join("shim"));
    for d in [&src, &obj, &shim.join("include"), &shim.join("src")] {
        std::fs::create_dir_all(d).map_err(io_err(d))?;
    }
    for (name, text) in SHIM {
        let p = shim.join(name);
        std::fs::write(&p, text).map_err(io_err(&p))?;
    }
    let mut jobs = Vec::new();
    for s in sources {
        // copied out of the tree: a quoted include then never finds the tree's file beside it
        let flat = s.rel.replace('/', "__");
        let copy = src.join(&flat);
        std::fs::copy(&s.path, &copy).map_err(io_err(&s.path))?;
        jobs.push(Job {
            label: s.rel.clone(),
            source: copy,
            object: obj.join(format!("fw__{flat}.o")),
            firmware: true,
        });
    }
    for (name, _) in SHIM.iter().filter(|(n, _)| n.ends_with(".c")) {
        let stem = Path::new(name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        jobs.push(Job {
            label: format!("shim/{name}"),
            source: shim.join(name),
            object: obj.join(format!("shim__{stem}.o")),
            firmware: false,
        });
    }
    let mut includes = vec![shim.join("include")];
    includes.extend(
        TREE_INCLUDE_DIRS
            .iter()
            .map(|d| tree.join(d))
            .filter(|p| p.is_dir()),
    );
    compile_all(cc, &jobs, &includes, defines)?;

    let exe = work.join(EXECUTABLE);
    let mut link = command(cc);
    link.arg("-o").arg(&exe);
    for j in &jobs {
        link.arg(&j.object);
    }
    for w in WRAPPED {
        link.arg(format!("-Wl,--wrap={w}"));
    }
    link.args(LINK_FLAGS);
    let out = link.output().map_err(|source| BuildError::Tool {
        tool: tool_name(cc),
        source,
    })?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        let mut undefined = parse_undefined(&stderr);
        if undefined.is_empty() {
            return Err(BuildError::Link {
                first_error: first_error_line(&stderr),
                stderr,
            });
        }
        let (symbol, object) = undefined.remove(0);
        let file = object.and_then(|o| {
            jobs.iter()
                .find(|j| {
                    j.object
                        .file_name()
                        .is_some_and(|f| f.to_string_lossy() == o)
                })
                .map(|j| j.label.clone())
        });
        return Err(BuildError::Undefined {
            symbol,
            file,
            others: undefined.into_iter().map(|(s, _)| s).collect(),
        });
    }

    let (mut fw_def, mut fw_undef, mut shim_def) =
        (BTreeSet::new(), BTreeSet::new(), BTreeSet::new());
    for j in &jobs {
        let (d, u) = nm_symbols(nm, &j.object)?;
        if j.firmware {
            fw_def.extend(d);
            fw_undef.extend(u);
        } else {
            shim_def.extend(d);
        }
    }
    let wrapped: BTreeSet<String> = WRAPPED.iter().map(|w| format!("__wrap_{w}")).collect();
    let stubbed = fw_undef
        .difference(&fw_def)
        .filter(|s| shim_def.contains(*s))
        .cloned()
        .chain(wrapped.into_iter().filter(|w| shim_def.contains(w)))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    Ok(Build {
        executable: exe,
        version,
        tree_hash: tree_hash.to_string(),
        compiled: sources.iter().map(|s| s.rel.clone()).collect(),
        stubbed,
        cached: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_from_conf_general() {
        let h = "#ifndef X\n// Firmware version\n#define FW_VERSION_MAJOR\t\t\t12\n#define FW_VERSION_MINOR  3\n";
        assert_eq!(parse_version(h), Some((12, 3)));
        assert_eq!(parse_version("#define FW_VERSION_MAJOR 10\n"), None);
        assert_eq!(
            parse_version("#define FW_VERSION_MAJOR ten\n#define FW_VERSION_MINOR 1\n"),
            None
        );
        // a longer name that starts the same is not the version
        assert_eq!(
            parse_version(
                "#define FW_VERSION_MAJOR_X 9\n#define FW_VERSION_MAJOR 10\n#define FW_VERSION_MINOR 1"
            ),
            Some((10, 1))
        );
    }

    #[test]
    fn main_parameters_from_main_c() {
        let m = "int main(void) {\n x_init();\n timeout_configure(1500, 40.0);\n for(;;) {\n  chThdSleepMilliseconds(10);\n  packet_timerfunc();\n }\n}";
        assert_eq!(
            parse_main(m),
            MainParams {
                timeout_ms: 1500,
                timeout_brake: 40.0,
                loop_ms: 10
            }
        );
        assert_eq!(
            parse_main("int main(void) { return 0; }"),
            MainParams::default()
        );
        assert_eq!(
            parse_main("timeout_configure(TIMEOUT, 2.0f);").timeout_ms,
            2000
        );
    }

    #[test]
    fn imu_callback_form() {
        assert!(imu_callback_without_args(
            "void mpu9150_set_read_callback(void(*func)(void));"
        ));
        assert!(imu_callback_without_args(
            "void mpu9150_set_read_callback( void (*func) (void) );"
        ));
        assert!(!imu_callback_without_args(
            "void mpu9150_set_read_callback(void(*func)(float *accel, float *gyro, float *mag));"
        ));
    }

    #[test]
    fn linker_errors_name_the_symbol_and_the_file() {
        let ld = "/usr/bin/ld: /c/.work-1/obj/fw__pos.c.o: in function `pos_init':\n\
                  pos.c:(.text+0x1a): undefined reference to `mpu9150_init'\n\
                  /usr/bin/ld: pos.c:(.text+0x2b): undefined reference to `ublox_send'\n\
                  /usr/bin/ld: /c/.work-1/obj/fw__commands.c.o: in function `x':\n\
                  commands.c:(.text+0x5): undefined reference to `mpu9150_init'\n\
                  collect2: error: ld returned 1 exit status\n";
        let u = parse_undefined(ld);
        assert_eq!(
            u,
            vec![
                ("mpu9150_init".to_string(), Some("fw__pos.c.o".to_string())),
                ("ublox_send".to_string(), Some("fw__pos.c.o".to_string()))
            ]
        );
        let lld =
            "ld.lld: error: undefined symbol: comm_can_dw_range\n>>> referenced by pos_uwb.c\n";
        assert_eq!(parse_undefined(lld)[0].0, "comm_can_dw_range");
        assert!(parse_undefined("collect2: error: ld returned 1 exit status").is_empty());
    }

    #[test]
    fn first_error_line_skips_notes() {
        let e = "In file included from x.c:1:\nx.h:3:1: warning: w\nx.c:9:5: error: expected ';'\nx.c:10:1: error: second\n";
        assert_eq!(first_error_line(e), "x.c:9:5: error: expected ';'");
        assert_eq!(first_error_line(""), "failed without a message");
    }

    #[test]
    fn nm_output() {
        let (d, u) = parse_nm(
            "0000000000000000 T pos_init\n                 U chMtxLock\n0000000000000010 b m_pos\n0000000000000008 D main_config\n0000000000000004 C common\n",
        );
        assert_eq!(
            d.into_iter().collect::<Vec<_>>(),
            ["common", "main_config", "pos_init"]
        );
        assert_eq!(u.into_iter().collect::<Vec<_>>(), ["chMtxLock"]);
    }

    fn fake_tree(dir: &Path, version: &str, skip: &str, broken: &str) {
        std::fs::write(dir.join("conf_general.h"), version).unwrap();
        for (name, _) in PORTABLE_SOURCES {
            if *name == skip {
                continue;
            }
            let stem = name.trim_end_matches(".c");
            let body = if *name == broken {
                "int broken(\n".to_string()
            } else {
                format!("int sitl_test_{stem};\n")
            };
            std::fs::write(dir.join(name), body).unwrap();
        }
    }

    const V10: &str = "#define FW_VERSION_MAJOR 10\n#define FW_VERSION_MINOR 1\n";

    #[test]
    fn refuses_what_is_not_a_tree() {
        let t = tempfile::tempdir().unwrap();
        let cache = t.path().join("cache");
        let missing = t.path().join("nope");
        assert!(matches!(
            build(&missing, &cache),
            Err(BuildError::NotATree { .. })
        ));
        assert!(
            matches!(build(t.path(), &cache), Err(BuildError::NotATree { reason, .. }) if reason.contains("conf_general.h"))
        );
        std::fs::write(t.path().join("conf_general.h"), "#define X 1\n").unwrap();
        let e = build(t.path(), &cache).unwrap_err();
        assert!(matches!(e, BuildError::NoVersion { .. }));
        assert!(e.to_string().contains("conf_general.h"), "{e}");
    }

    #[test]
    fn a_missing_portable_source_is_named() {
        let t = tempfile::tempdir().unwrap();
        fake_tree(t.path(), V10, "pos_uwb.c", "");
        let e = build(t.path(), &t.path().join("cache")).unwrap_err();
        assert!(
            matches!(&e, BuildError::MissingSource { name, .. } if name == "pos_uwb.c"),
            "{e}"
        );
        // an optional one may be missing: the build goes on (and fails later, at the shim)
        let t = tempfile::tempdir().unwrap();
        fake_tree(t.path(), V10, "digital_filter.c", "");
        assert!(!matches!(
            build(t.path(), &t.path().join("cache")),
            Err(BuildError::MissingSource { .. })
        ));
    }

    #[test]
    fn a_compile_error_names_the_file_and_the_first_error() {
        let t = tempfile::tempdir().unwrap();
        fake_tree(t.path(), V10, "", "commands.c");
        let e = build(t.path(), &t.path().join("cache")).unwrap_err();
        match &e {
            BuildError::Compile {
                file, first_error, ..
            } => {
                assert_eq!(file, "commands.c");
                assert!(first_error.contains("error"), "{first_error}");
            }
            other => panic!("expected a compile error, got {other}"),
        }
        // the failed build left no work folder behind
        let left: Vec<_> = std::fs::read_dir(t.path().join("cache")).unwrap().collect();
        assert!(left.is_empty(), "{left:?}");
    }

    #[test]
    fn a_tool_variable_may_carry_arguments() {
        let (p, args) = tool_command("SITL_TEST_UNSET_VARIABLE", "cc --flag");
        assert_eq!(p, OsString::from("cc"));
        assert_eq!(args, vec![OsString::from("--flag")]);
    }

    #[test]
    fn the_shim_is_embedded_whole() {
        for (name, text) in shim_sources() {
            assert!(!text.is_empty(), "{name}");
            assert!(
                text.contains("drivecheck"),
                "{name} has no drivecheck header"
            );
        }
        let c: Vec<_> = shim_sources()
            .iter()
            .filter(|(n, _)| n.ends_with(".c"))
            .collect();
        assert_eq!(c.len(), 5);
    }

    /// The kernel subset alone (`shim/test/rt_test.c`): wake-up order, mutex hand-over and
    /// priority, tick-aligned delays, virtual timers, events and semaphores with time-outs, a
    /// periodic thread, and the self-deadlock report.
    #[test]
    fn the_shim_kernel_behaves() {
        let t = tempfile::tempdir().unwrap();
        for (name, text) in shim_sources() {
            let p = t.path().join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        }
        let test = t.path().join("rt_test.c");
        std::fs::write(&test, include_str!("../shim/test/rt_test.c")).unwrap();
        let exe = t.path().join("rt_test");
        let cc = tool_command("CC", "cc");
        let out = command(&cc)
            .args([
                "-std=gnu99",
                "-O2",
                "-Wall",
                "-Wextra",
                "-Werror",
                "-Wno-unused-parameter",
            ])
            .arg("-I")
            .arg(t.path().join("include"))
            .arg("-I")
            .arg(t.path().join("src"))
            .arg(&test)
            .arg(t.path().join("src/sitl_rt.c"))
            .arg("-o")
            .arg(&exe)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let run = Command::new(&exe).output().unwrap();
        let stdout = String::from_utf8_lossy(&run.stdout);
        assert!(run.status.success() && stdout.ends_with("ok\n"), "{stdout}");
        let run = Command::new(&exe).arg("deadlock").output().unwrap();
        let stdout = String::from_utf8_lossy(&run.stdout);
        assert_eq!(run.status.code(), Some(3), "{stdout}");
        assert!(
            stdout.contains("locks a mutex it already holds"),
            "{stdout}"
        );
    }
}
