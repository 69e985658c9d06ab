//! `drivecheck-dev bench compare`: how `drivecheck compare` decides, measured on the simulated car
//! (`docs/compare.md`, *How many tests a difference needs*).
//!
//! One set of cases is generated; every run drives exactly those cases (`run --cases-from`) in
//! virtual time, each with a seed of its own, as a `drivecheck` process of its own. Pairs of runs
//! on the same car measure the false alarms and the noise of a segment's largest deviation;
//! pairs of a same-car run and a degraded car's run measure how often the regression is found
//! with a quarter, half and all of the tests; one run on firmware 12.3 is compared with one on
//! 10.1.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, Result, bail};

use crate::cli::BenchCompareArgs;
use campaign::compare::{
    BreakdownRow, Options, Report, Significance, TestRow, compare, nearest_rank, pair,
};
use orchestrator::commands::compare::{DEFAULT_NOISE_M, read_rows};
use orchestrator::commands::scratch::Scratch;
use orchestrator::exit::Exit;

/// A car of the bench: its name and its profile's TOML (`None`: the default car).
struct Car {
    name: &'static str,
    profile: Option<&'static str>,
}

/// The degraded cars (each against the default car, whose ranging σ is 0.1 m, whose anchors'
/// range biases are drawn from 0–0.25 m by their ids and whose firmware clamps a UWB correction
/// to 0.2 m per range: `docs/twin.md`).
const DEGRADED: [Car; 4] = [
    Car {
        name: "ranging σ 0.15 m (1.5×)",
        profile: Some("[radio]\nrange_sigma_m = 0.15\n"),
    },
    Car {
        name: "ranging σ 0.2 m (2×)",
        profile: Some("[radio]\nrange_sigma_m = 0.2\n"),
    },
    Car {
        name: "anchor 50 biased 0.5 m",
        profile: Some("[anchors.\"50\"]\nrange_bias_m = 0.5\n"),
    },
    Car {
        name: "a firmware build clamping a UWB correction to 0.5 m",
        profile: Some("[estimator]\nuwb_correction_clamp_m = 0.5\n"),
    },
];

/// Firmware 12.3 on the default car otherwise.
const FIRMWARE_12: Car = Car {
    name: "firmware 12.3",
    profile: Some("firmware = \"12.3\"\n"),
};

/// Measures and prints the tables: on the simulated car, or on the firmware with `--car
/// sitl:TREE` ([`super::compare_firmware`]).
pub fn run(args: &BenchCompareArgs) -> Result<Exit> {
    match args.car.as_str() {
        "sim" if args.candidate.is_none() => simulated(args),
        "sim" => bail!("--candidate needs --car sitl:TREE"),
        car => match car.strip_prefix("sitl:") {
            Some(tree) if !tree.is_empty() => super::compare_firmware::run(args, Path::new(tree)),
            _ => bail!("--car {car}: bench compare drives `sim` or `sitl:TREE`"),
        },
    }
}

/// The tables on the embedded simulated car.
fn simulated(args: &BenchCompareArgs) -> Result<Exit> {
    let exe = std::env::current_exe().context("cannot find the drivecheck-dev executable")?;
    let (_scratch, root) = Scratch::given_or_new(args.scratch.as_deref(), "bench", "compare")?;
    let pairs = args.pairs as usize;
    let sizes = [args.tests / 4, args.tests / 2, args.tests];
    println!(
        "bench compare: {} cases of seed {} on parking-lot-2anchors, each run with a seed of its \
         own (virtual time); α = 0.05; sizes: the first {}, {} and {} tests\n",
        args.tests, args.seed, sizes[0], sizes[1], sizes[2]
    );
    let cases = root.join("cases");
    let tests = args.tests.to_string();
    let seed = args.seed.to_string();
    drive(&exe, &["--seed", &seed, "--tests", &tests], &cases)?;
    let mut next_seed = args.seed;
    let mut again = |car: &Car, name: &str| -> Result<Vec<TestRow>> {
        next_seed += 1;
        let out = root.join(name);
        let seed = next_seed.to_string();
        let mut run_args = vec!["--cases-from", path(&cases)?, "--seed", &seed];
        let profile = root.join(format!("{name}.toml"));
        if let Some(toml) = car.profile {
            std::fs::write(
                &profile,
                format!("format = \"drivecheck-car-profile\"\nversion = 1\n{toml}"),
            )
            .with_context(|| format!("cannot write {}", profile.display()))?;
            run_args.extend(["--profile", path(&profile)?]);
        }
        drive(&exe, &run_args, &out)?;
        read_rows(&out)
    };
    let default_car = Car {
        name: "the default car",
        profile: None,
    };
    let same: Vec<(Vec<TestRow>, Vec<TestRow>)> = (0..pairs)
        .map(|k| {
            Ok((
                again(&default_car, &format!("same-{k}-a"))?,
                again(&default_car, &format!("same-{k}-b"))?,
            ))
        })
        .collect::<Result<_>>()?;

    // The noise: |change| of every segment measured in both runs of a same-car pair.
    let mut changes = Vec::new();
    for (a, b) in &same {
        let paired = pair(a.clone(), b.clone())?;
        changes.extend(paired.segments().filter_map(|s| s.change_m()).map(f64::abs));
    }
    changes.sort_by(f64::total_cmp);
    let noise = nearest_rank(&changes, 0.95).context("no segment measured in both runs")?;
    let share_within = |limit: f64| {
        changes.iter().filter(|&&c| c <= limit).count() as f64 / changes.len().max(1) as f64
    };
    println!(
        "noise (same car, other seed): a segment's largest deviation changed by at most {noise:.3} m \
         in 95 % of {} segments paired over {pairs} pairs; {:.1} % within the default {DEFAULT_NOISE_M} m; \
         median {:.3} m\n",
        changes.len(),
        100.0 * share_within(DEFAULT_NOISE_M),
        nearest_rank(&changes, 0.5).unwrap_or(f64::NAN)
    );

    println!("| car (BASE: the default car) | {} |", {
        sizes
            .iter()
            .map(|n| format!("{n} tests"))
            .collect::<Vec<_>>()
            .join(" | ")
    });
    println!("|---|{}", "---|".repeat(sizes.len()));
    let found = |comparisons: &[Vec<Report>], want: Significance| -> String {
        (0..sizes.len())
            .map(|i| {
                let k = comparisons
                    .iter()
                    .filter(|by_size| by_size[i].significance == want)
                    .count();
                format!("{k} of {}", comparisons.len())
            })
            .collect::<Vec<_>>()
            .join(" | ")
    };
    let same_reports: Vec<Vec<Report>> = same
        .iter()
        .map(|(a, b)| by_size(a, b, &sizes, noise))
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
                "{} of {pairs} (false alarms: McNemar {}, sign flips {})",
                raised.len(),
                by(|r| r.evidence.verdicts_worse || r.evidence.verdicts_better),
                by(|r| r.evidence.deviation_worse || r.evidence.deviation_better)
            )
        })
        .collect::<Vec<_>>()
        .join(" | ");
    println!("| the default car, other seed | {alarms} |");
    let mut where_found = Vec::new();
    for car in &DEGRADED {
        let mut reports = Vec::new();
        for (k, (base, _)) in same.iter().enumerate() {
            let slug: String = car
                .name
                .chars()
                .filter(char::is_ascii_alphanumeric)
                .collect();
            let degraded = again(car, &format!("{slug}-{k}"))?;
            reports.push(by_size(base, &degraded, &sizes, noise)?);
        }
        println!(
            "| {} | {} (found worse) |",
            car.name,
            found(&reports, Significance::Worse)
        );
        if let Some(first) = reports.first().and_then(|r| r.last()) {
            where_found.push((car.name, first.clone()));
        }
    }
    println!(
        "\nwhere the difference lives ({} tests, the first pair):",
        args.tests
    );
    for (name, report) in &where_found {
        println!(
            "- {name}: {}; fault rows {}; first region row {}",
            report.verdict,
            first_rows(&report.breakdowns.by_fault, 3),
            top(&report.breakdowns.by_region)
        );
    }
    let firmware = again(&FIRMWARE_12, "firmware-12")?;
    let report = by_size(&same[0].0, &firmware, &sizes, noise)?;
    if let Some(full) = report.last() {
        println!(
            "\nfirmware 10.1 (BASE) against {} (NEW), {} tests: {}",
            FIRMWARE_12.name, args.tests, full.verdict
        );
        println!(
            "  first fault row {}; first speed row {}",
            top(&full.breakdowns.by_fault),
            top(&full.breakdowns.by_speed)
        );
    }
    Ok(Exit::Success)
}

/// BASE against NEW over the first `n` tests for every `n` of `sizes`, with the noise `noise`.
pub(super) fn by_size(
    base: &[TestRow],
    new: &[TestRow],
    sizes: &[usize],
    noise: f64,
) -> Result<Vec<Report>> {
    sizes
        .iter()
        .map(|&n| {
            let first = |rows: &[TestRow]| -> Vec<TestRow> {
                rows.iter().filter(|r| r.test_index < n).cloned().collect()
            };
            let paired = pair(first(base), first(new))?;
            Ok(compare(&paired, &Options::with_noise(noise))?)
        })
        .collect()
}

/// A breakdown's first `n` rows in words.
pub(super) fn first_rows(rows: &[BreakdownRow], n: usize) -> String {
    rows.iter()
        .take(n)
        .map(|row| top(std::slice::from_ref(row)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A breakdown's first row in words.
pub(super) fn top(rows: &[BreakdownRow]) -> String {
    rows.first().map_or_else(
        || "-".to_owned(),
        |row| {
            format!(
                "`{}` ({} segments, median {:+.3} m, {} worse and {} better than the noise)",
                row.key,
                row.segments,
                row.median_change_m.unwrap_or(f64::NAN),
                row.worse,
                row.better
            )
        },
    )
}

/// `drivecheck -q run ARGS --record none --out OUT`, its output discarded; it must end with 0
/// or 1.
fn drive(exe: &Path, args: &[&str], out: &PathBuf) -> Result<()> {
    drive_with(exe, args, out, &[])
}

/// [`drive`] with environment variables of its own.
pub(super) fn drive_with(
    exe: &Path,
    args: &[&str],
    out: &PathBuf,
    env: &[(&str, &std::ffi::OsStr)],
) -> Result<()> {
    let status = Command::new(exe)
        .envs(env.iter().copied())
        .arg("exec")
        .args(["-q", "run"])
        .args(args)
        .args(["--record", "none", "--out"])
        .arg(out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    match status.code() {
        Some(0 | 1) => Ok(()),
        _ => bail!("drivecheck run {} ended with {status}", args.join(" ")),
    }
}

pub(super) fn path(p: &Path) -> Result<&str> {
    p.to_str()
        .with_context(|| format!("{}: not a UTF-8 path", p.display()))
}
