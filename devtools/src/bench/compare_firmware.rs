//! `drivecheck-dev bench compare --car sitl:TREE`: the firmware regression gate of
//! `docs/sitl.md` (*A firmware regression gate*), measured on the car's own firmware.
//!
//! One run on the BASE tree makes the cases (the gate's BASE run). Then, every run driving
//! exactly those cases (`run --cases-from`) in virtual time, each a `drivecheck` process of its
//! own:
//!
//! - the gate as its recipe runs it, the same tree as candidate, the BASE run's own seed: the
//!   same firmware and seed give the same case files, so no change and no alarm;
//! - pairs of runs of the BASE tree with seeds of their own: the false alarms of a candidate
//!   that changes nothing but the car's noise (the worst case of an unchanged firmware);
//! - degraded copies of the BASE tree (a small change of one named constant, made in the scratch
//!   directory with `sitl::variant`, never in the tree), and the `--candidate` tree if given,
//!   each run with the seed of a pair's first run and compared with it, as the recipe pairs a
//!   candidate with its BASE run: how often the gate finds them worse (its power).
//!
//! Also what the gate costs: each tree's cold build and cached build, and the wall time of the
//! runs.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use super::compare::{by_size, drive_with, first_rows, path, top};
use crate::cli::BenchCompareArgs;
use campaign::compare::{Report, Significance, TestRow, nearest_rank, pair};
use orchestrator::commands::compare::{DEFAULT_NOISE_M, read_rows};
use orchestrator::commands::scratch::Scratch;
use orchestrator::exit::Exit;

/// A small change of one named constant of a tree, the kind a firmware team commits by
/// mistake (`docs/sitl.md#a-firmware-regression-gate` says each in words).
pub struct Degradation {
    /// In words.
    pub name: &'static str,
    /// The firmware's major version it applies to (its file and constant are that generation's).
    pub major: u8,
    /// The file, relative to the tree.
    pub file: &'static str,
    /// The macro or field (`sitl::variant::set_constant`).
    pub constant: &'static str,
    /// Its new number.
    pub value: &'static str,
}

/// The degradations the bench makes of a BASE tree of their generation.
pub const DEGRADATIONS: [Degradation; 3] = [
    Degradation {
        name: "10.x: the UWB antenna's offset entered with the wrong sign",
        major: 10,
        file: "pos_uwb.c",
        constant: "OFFSET_X",
        value: "-0.085",
    },
    Degradation {
        name: "10.x: the UWB correction step raised from 0.2 to 0.5 m",
        major: 10,
        file: "pos_uwb.c",
        constant: "CORR_STEP",
        value: "0.5",
    },
    Degradation {
        name: "12.x: the UWB correction gate tightened from 0.1 to 0.02 m",
        major: 12,
        file: "conf_general.c",
        constant: "uwb_max_corr",
        value: "0.02",
    },
];

/// A tree the bench drives, built.
struct Tree {
    name: String,
    path: PathBuf,
    cold: Duration,
    cached: Duration,
}

/// Builds `tree` into `cache` twice (cold, then from the cache), timing both.
fn built(name: String, tree: &Path, cache: &Path) -> Result<(Tree, (u8, u8))> {
    let t = Instant::now();
    let build = sitl::build(tree, cache).with_context(|| format!("{name}: the build failed"))?;
    let cold = t.elapsed();
    let t = Instant::now();
    let again = sitl::build(tree, cache).with_context(|| format!("{name}: the build failed"))?;
    let cached = t.elapsed();
    if !again.cached {
        bail!("{name}: the second build did not come from the cache");
    }
    Ok((
        Tree {
            name,
            path: tree.to_owned(),
            cold,
            cached,
        },
        build.version,
    ))
}

/// Measures and prints the gate's figures on the firmware tree `base`.
pub fn run(args: &BenchCompareArgs, base: &Path) -> Result<Exit> {
    let exe = std::env::current_exe().context("cannot find the drivecheck-dev executable")?;
    let (_scratch, root) = Scratch::given_or_new(args.scratch.as_deref(), "bench", "compare")?;
    let cache = root.join("sitl-cache");
    let env = [("DRIVECHECK_SITL_CACHE", cache.as_os_str())];
    let pairs = args.pairs as usize;
    let sizes = [args.tests / 4, args.tests / 2, args.tests];

    let (base_tree, version) = built("BASE".to_owned(), base, &cache)?;
    let mut candidates = Vec::new();
    for d in DEGRADATIONS.iter().filter(|d| d.major == version.0) {
        let slug: String = d.name.chars().filter(char::is_ascii_alphanumeric).collect();
        let copy = root.join(format!("tree-{slug}"));
        sitl::variant::copy_tree(base, &copy)?;
        let old = sitl::variant::set_constant(&copy, d.file, d.constant, d.value)
            .with_context(|| format!("cannot make the degraded tree `{}`", d.name))?;
        let (tree, _) = built(
            format!(
                "{} (`{}` in {}: {old} → {})",
                d.name, d.constant, d.file, d.value
            ),
            &copy,
            &cache,
        )?;
        candidates.push(tree);
    }
    if let Some(candidate) = &args.candidate {
        let (tree, v) = built(
            format!("the candidate {}", candidate.display()),
            candidate,
            &cache,
        )?;
        if v.0 != version.0 {
            println!(
                "note: the candidate is firmware {}.{}, BASE {}.{}",
                v.0, v.1, version.0, version.1
            );
        }
        candidates.push(tree);
    }
    println!(
        "bench compare on the firmware: BASE {} (firmware {}.{}); {} cases of seed {} on \
         parking-lot-2anchors; virtual time; α = 0.05; sizes: the first {}, {} and {} tests\n",
        base.display(),
        version.0,
        version.1,
        args.tests,
        args.seed,
        sizes[0],
        sizes[1],
        sizes[2]
    );

    let wall = std::cell::RefCell::new(Vec::new());
    let drive = |tree: &Tree, extra: &[&str], out: &Path| -> Result<Vec<TestRow>> {
        let car = format!("sitl:{}", path(&tree.path)?);
        let mut all = vec!["--car", &car];
        all.extend_from_slice(extra);
        let t = Instant::now();
        drive_with(&exe, &all, &out.to_owned(), &env)?;
        wall.borrow_mut().push(t.elapsed());
        read_rows(out)
    };

    let cases = root.join("base");
    let tests = args.tests.to_string();
    let seed = args.seed.to_string();
    let base_rows = drive(&base_tree, &["--seed", &seed, "--tests", &tests], &cases)?;
    let base_wall = wall.borrow()[0];
    let from = path(&cases)?.to_owned();
    // The recipe on an unchanged firmware: the BASE run's own seed.
    let recipe = drive(
        &base_tree,
        &["--cases-from", &from],
        &root.join("recipe-same"),
    )?;
    let recipe_report = by_size(&base_rows, &recipe, &sizes, DEFAULT_NOISE_M)?;
    let largest = pair(base_rows.clone(), recipe.clone())?
        .segments()
        .filter_map(|s| s.change_m())
        .map(f64::abs)
        .fold(0.0, f64::max);

    let mut next_seed = args.seed;
    let mut same = Vec::new();
    for k in 0..pairs {
        let mut run = |name: String| -> Result<(u64, Vec<TestRow>)> {
            next_seed += 1;
            let s = next_seed.to_string();
            let rows = drive(
                &base_tree,
                &["--cases-from", &from, "--seed", &s],
                &root.join(name),
            )?;
            Ok((next_seed, rows))
        };
        let a = run(format!("same-{k}-a"))?;
        let b = run(format!("same-{k}-b"))?;
        same.push((a, b));
    }

    let mut changes = Vec::new();
    for ((_, a), (_, b)) in &same {
        let paired = pair(a.clone(), b.clone())?;
        changes.extend(paired.segments().filter_map(|s| s.change_m()).map(f64::abs));
    }
    changes.sort_by(f64::total_cmp);
    let noise = nearest_rank(&changes, 0.95).context("no segment measured in both runs")?;
    println!(
        "noise (same firmware, other seed): a segment's largest deviation changed by at most \
         {noise:.3} m in 95 % of {} segments paired over {pairs} pairs; {:.1} % within the \
         default {DEFAULT_NOISE_M} m; median {:.3} m\n",
        changes.len(),
        100.0 * changes.iter().filter(|&&c| c <= DEFAULT_NOISE_M).count() as f64
            / changes.len().max(1) as f64,
        nearest_rank(&changes, 0.5).unwrap_or(f64::NAN)
    );

    let header = sizes
        .iter()
        .map(|n| format!("{n} tests"))
        .collect::<Vec<_>>()
        .join(" | ");
    println!("| candidate (BASE: the BASE tree) | {header} |");
    println!("|---|{}", "---|".repeat(sizes.len()));
    let verdicts = |reports: &[Report]| -> String {
        reports
            .iter()
            .map(|r| match r.significance {
                Significance::Worse => "worse",
                Significance::Better => "better",
                Significance::Mixed => "mixed",
                Significance::NoDifference => "no difference",
            })
            .collect::<Vec<_>>()
            .join(" | ")
    };
    println!(
        "| the BASE tree, the BASE run's seed (the recipe): largest |change| {largest:.3} m | {} |",
        verdicts(&recipe_report)
    );
    let same_reports: Vec<Vec<Report>> = same
        .iter()
        .map(|((_, a), (_, b))| by_size(a, b, &sizes, noise))
        .collect::<Result<_>>()?;
    let alarms = (0..sizes.len())
        .map(|i| {
            let raised: Vec<&Report> = same_reports
                .iter()
                .map(|r| &r[i])
                .filter(|r| r.significance != Significance::NoDifference)
                .collect();
            let by = |test: fn(&Report) -> bool| raised.iter().filter(|r| test(r)).count();
            format!(
                "{} of {pairs} (false alarms: McNemar {}, sign flips {}; worse {})",
                raised.len(),
                by(|r| r.evidence.verdicts_worse || r.evidence.verdicts_better),
                by(|r| r.evidence.deviation_worse || r.evidence.deviation_better),
                by(|r| r.significance == Significance::Worse
                    || r.significance == Significance::Mixed)
            )
        })
        .collect::<Vec<_>>()
        .join(" | ");
    println!("| the BASE tree, other seeds | {alarms} |");

    let mut where_found = Vec::new();
    for (c, candidate) in candidates.iter().enumerate() {
        let mut reports = Vec::new();
        for (k, ((seed, a), _)) in same.iter().enumerate() {
            let s = seed.to_string();
            let rows = drive(
                candidate,
                &["--cases-from", &from, "--seed", &s],
                &root.join(format!("candidate-{c}-{k}")),
            )?;
            reports.push(by_size(a, &rows, &sizes, noise)?);
        }
        let found = (0..sizes.len())
            .map(|i| {
                let worse = reports
                    .iter()
                    .filter(|r| {
                        matches!(r[i].significance, Significance::Worse | Significance::Mixed)
                    })
                    .count();
                format!("{worse} of {}", reports.len())
            })
            .collect::<Vec<_>>()
            .join(" | ");
        println!("| {} | {found} (gate fails) |", candidate.name);
        if let Some(first) = reports.first().and_then(|r| r.last()) {
            where_found.push((&candidate.name, first.clone()));
        }
    }
    println!(
        "\nwhere the difference lives ({} tests, the first pair):",
        args.tests
    );
    for (name, report) in &where_found {
        println!(
            "- {name}: {}; fault rows {}; first speed row {}",
            report.verdict,
            first_rows(&report.breakdowns.by_fault, 3),
            top(&report.breakdowns.by_speed)
        );
    }

    let secs = |d: &Duration| d.as_secs_f64();
    println!("\ncost:");
    for tree in std::iter::once(&base_tree).chain(&candidates) {
        println!(
            "- build of {}: cold {:.1} s, from the cache {:.3} s",
            tree.name,
            secs(&tree.cold),
            secs(&tree.cached)
        );
    }
    let mut all: Vec<f64> = wall.borrow().iter().map(secs).collect();
    all.sort_by(f64::total_cmp);
    println!(
        "- a run of {} tests (`drivecheck run --car sitl:TREE --record none`, one process, \
         --jobs 1): the BASE run {:.1} s; over all {} runs median {:.1} s, max {:.1} s wall",
        args.tests,
        secs(&base_wall),
        all.len(),
        nearest_rank(&all, 0.5).unwrap_or(f64::NAN),
        all.last().copied().unwrap_or(f64::NAN)
    );
    Ok(Exit::Success)
}
