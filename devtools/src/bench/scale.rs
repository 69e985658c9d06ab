//! `drivecheck-dev bench scale`: what a campaign and every reader of its run directory cost as the
//! campaign grows (`docs/scaling.md`, *Figures*). Each step is a process of its own (this
//! executable's `exec`, the `drivecheck` command run in process), so that its peak memory is its
//! own: the child writes its peak resident set (`VmHWM` of `/proc/self/status`) to the file named
//! by [`PEAK_MEMORY_ENV`] as it exits. The `drivecheck` binary itself has no such hook.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use crate::cli::BenchScaleArgs;
use orchestrator::commands::scratch::Scratch;
use orchestrator::exit::Exit;

/// The environment variable naming the file a `drivecheck` process writes its peak resident set
/// to (kB, as Linux counts it) when it exits; see [`record_peak_memory`].
pub const PEAK_MEMORY_ENV: &str = "DRIVECHECK_PEAK_MEMORY_FILE";

/// When [`PEAK_MEMORY_ENV`] names a file, writes this process's peak resident set to it (kB; the
/// `VmHWM` line of `/proc/self/status`, Linux only: elsewhere nothing is written). `exec` calls
/// it as the process ends.
pub fn record_peak_memory() {
    let Some(file) = std::env::var_os(PEAK_MEMORY_ENV) else {
        return;
    };
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return;
    };
    if let Some(kb) = status
        .lines()
        .find_map(|line| line.strip_prefix("VmHWM:"))
        .and_then(|rest| {
            rest.trim()
                .trim_end_matches("kB")
                .trim()
                .parse::<u64>()
                .ok()
        })
    {
        let _ = std::fs::write(file, kb.to_string());
    }
}

/// One step measured: its wall time and peak resident set.
#[derive(Debug, Clone, Copy)]
struct Cost {
    wall: Duration,
    peak_mb: Option<f64>,
}

/// What one campaign size cost.
#[derive(Debug)]
struct SizeRow {
    tests: usize,
    campaign: Cost,
    unrecorded: Cost,
    mb_per_test: f64,
    failing: usize,
    show: Cost,
    report: Cost,
    report_mb: f64,
    explain: Cost,
    merge: Cost,
}

/// Measures every size of `args` and prints the tables.
pub fn run(args: &BenchScaleArgs) -> Result<Exit> {
    let exe = std::env::current_exe().context("cannot find the drivecheck-dev executable")?;
    let (_scratch, root) = Scratch::given_or_new(args.scratch.as_deref(), "bench", "scale")?;
    println!(
        "bench scale: seed {}, --jobs {}, {}; each step a process of its own (peak memory: its \
         VmHWM)",
        args.seed,
        args.jobs,
        if args.unrecorded_only {
            "only the campaign with --record none"
        } else {
            "--record failing"
        }
    );
    if args.unrecorded_only {
        let mut costs = Vec::new();
        for &tests in &args.sizes {
            let dir = root.join(format!("{tests}"));
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            let cost = step(
                &exe,
                &dir,
                &campaign_args(&dir.join("unrecorded"), tests, args, "none"),
                &[0, 1],
            )?;
            eprintln!(
                "{tests} tests, --record none: {:.1} s, {:.1} MB peak",
                cost.wall.as_secs_f64(),
                cost.peak_mb.unwrap_or(f64::NAN)
            );
            costs.push((tests, cost));
        }
        print_unrecorded(&costs);
        return Ok(Exit::Success);
    }
    let mut rows = Vec::new();
    for &tests in &args.sizes {
        let row = measure(&exe, &root.join(format!("{tests}")), tests, args)?;
        eprintln!(
            "{tests} tests: campaign {:.1} s, {:.1} MB peak",
            row.campaign.wall.as_secs_f64(),
            row.campaign.peak_mb.unwrap_or(f64::NAN)
        );
        rows.push(row);
    }
    print_rows(&rows);
    Ok(Exit::Success)
}

fn measure(exe: &Path, dir: &Path, tests: usize, args: &BenchScaleArgs) -> Result<SizeRow> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let run = dir.join("run");
    let campaign_args = |out: &Path, record: &str| campaign_args(out, tests, args, record);
    // A campaign whose tests fail ends with status 1: that is what is measured.
    let campaign = step(exe, dir, &campaign_args(&run, "failing"), &[0, 1])?;
    let unrecorded = step(
        exe,
        dir,
        &campaign_args(&dir.join("unrecorded"), "none"),
        &[0, 1],
    )?;
    let recording = std::fs::metadata(run.join(runner::RECORDING_FILE))
        .map(|m| m.len())
        .unwrap_or(0);
    let failing = count_failing(&run)?;
    let run_arg = run.display().to_string();
    let show = step(
        exe,
        dir,
        &["runs".into(), "show".into(), run_arg.clone()],
        &[0, 1],
    )?;
    let report_file = dir.join("report.html");
    let report = step(
        exe,
        dir,
        &[
            "report".into(),
            run_arg.clone(),
            "--out".into(),
            report_file.display().to_string(),
        ],
        &[0],
    )?;
    let report_mb = (size_of(&report_file) + size_of(&report_file.with_extension(""))) as f64 / 1e6;
    let explain = step(exe, dir, &["explain".into(), run_arg], &[0, 1])?;
    let mut shards = Vec::new();
    for k in 1..=2 {
        let out = dir.join(format!("shard-{k}"));
        let mut shard_args = campaign_args(&out, "failing");
        shard_args.extend(["--shard".into(), format!("{k}/2")]);
        step(exe, dir, &shard_args, &[0, 1])?;
        shards.push(out.display().to_string());
    }
    let mut merge_args = vec!["runs".to_owned(), "merge".to_owned()];
    merge_args.extend(shards);
    merge_args.extend(["--out".into(), dir.join("merged").display().to_string()]);
    let merge = step(exe, dir, &merge_args, &[0, 1])?;
    Ok(SizeRow {
        tests,
        campaign,
        unrecorded,
        mb_per_test: recording as f64 / 1e6 / tests as f64,
        failing,
        show,
        report,
        report_mb,
        explain,
        merge,
    })
}

/// `drivecheck -q run` of `tests` tests with the bench's seed and jobs, recording as `record`
/// says, into `out`.
fn campaign_args(out: &Path, tests: usize, args: &BenchScaleArgs, record: &str) -> Vec<String> {
    vec![
        "-q".into(),
        "run".into(),
        "--tests".into(),
        tests.to_string(),
        "--seed".into(),
        args.seed.to_string(),
        "--jobs".into(),
        args.jobs.to_string(),
        "--record".into(),
        record.into(),
        "--out".into(),
        out.display().to_string(),
    ]
}

/// The least-squares line through `(tests, peak MB)`: the peak at no test (MB) and what each
/// test adds (kB); `None` with fewer than two sizes or without a peak.
fn memory_slope(points: &[(usize, Option<f64>)]) -> Option<(f64, f64)> {
    let known: Vec<(f64, f64)> = points
        .iter()
        .filter_map(|&(n, mb)| mb.map(|mb| (n as f64, mb)))
        .collect();
    if known.len() < 2 {
        return None;
    }
    let count = known.len() as f64;
    let mean_n = known.iter().map(|p| p.0).sum::<f64>() / count;
    let mean_mb = known.iter().map(|p| p.1).sum::<f64>() / count;
    let spread: f64 = known.iter().map(|p| (p.0 - mean_n).powi(2)).sum();
    if spread == 0.0 {
        return None;
    }
    let slope = known
        .iter()
        .map(|p| (p.0 - mean_n) * (p.1 - mean_mb))
        .sum::<f64>()
        / spread;
    Some((mean_mb - slope * mean_n, slope * 1e3))
}

/// The line of what a test adds to the peak memory of the campaign with `--record none`.
fn print_slope(points: &[(usize, Option<f64>)]) {
    if let Some((base, kb)) = memory_slope(points) {
        println!(
            "memory per test with --record none: {kb:.2} kB (least squares over {} sizes: \
             peak = {base:.1} MB + {kb:.2} kB × tests; 1,000,000 tests: {:.0} MB)",
            points.len(),
            base + kb * 1e3
        );
        if points.iter().map(|p| p.0).max().unwrap_or(0) < 1_000 {
            println!(
                "  (below 1,000 tests the peaks differ by what start-up and the allocator take, \
                 not by the tests: give larger --sizes for the slope)"
            );
        }
    }
}

/// The table of `--unrecorded-only`.
fn print_unrecorded(costs: &[(usize, Cost)]) {
    println!();
    println!("{:>9} {:>12} {:>8}", "tests", "unrecorded s", "peak MB");
    for (tests, cost) in costs {
        println!(
            "{:>9} {:>12.1} {:>8}",
            tests,
            cost.wall.as_secs_f64(),
            cost.peak_mb.map_or("?".to_owned(), |m| format!("{m:.1}"))
        );
    }
    println!();
    print_slope(
        &costs
            .iter()
            .map(|(tests, cost)| (*tests, cost.peak_mb))
            .collect::<Vec<_>>(),
    );
}

/// Runs `drivecheck ARGS` in `dir`, its output discarded; its status must be one of `ok`.
fn step(exe: &Path, dir: &Path, args: &[String], ok: &[i32]) -> Result<Cost> {
    let peak_file = dir.join(".peak-memory");
    let _ = std::fs::remove_file(&peak_file);
    let started = Instant::now();
    let status = Command::new(exe)
        .arg("exec")
        .args(args)
        .current_dir(dir)
        .env(PEAK_MEMORY_ENV, &peak_file)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    let wall = started.elapsed();
    match status.code() {
        Some(code) if ok.contains(&code) => {}
        _ => bail!("drivecheck {} ended with {status}", args.join(" ")),
    }
    let peak_mb = std::fs::read_to_string(&peak_file)
        .ok()
        .and_then(|kb| kb.trim().parse::<f64>().ok())
        .map(|kb| kb * 1024.0 / 1e6);
    Ok(Cost { wall, peak_mb })
}

/// The tests of the run directory that did not pass (from `campaign.json`'s summary).
fn count_failing(run: &Path) -> Result<usize> {
    let path = run.join(runner::CAMPAIGN_FILE);
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let record = campaign::files::CampaignRecord::from_json(&text)
        .with_context(|| format!("{}", path.display()))?;
    Ok(record
        .summary
        .map(|s| s.tests.saturating_sub(s.passed))
        .unwrap_or(0))
}

/// Bytes of a file, or of every file under a directory; 0 when absent.
fn size_of(path: &Path) -> u64 {
    let Ok(meta) = std::fs::metadata(path) else {
        return 0;
    };
    if meta.is_file() {
        return meta.len();
    }
    std::fs::read_dir(path)
        .map(|entries| entries.flatten().map(|e| size_of(&e.path())).sum())
        .unwrap_or(0)
}

fn print_rows(rows: &[SizeRow]) {
    let mb = |c: &Cost| c.peak_mb.map_or("?".to_owned(), |m| format!("{m:.0}"));
    println!();
    println!(
        "{:>7} {:>7} {:>11} {:>6} {:>8} | peak MB: {:>5} {:>5} {:>6} {:>7} {:>5} | {:>9}",
        "tests",
        "failing",
        "campaign s",
        "×rec",
        "MB/test",
        "run",
        "show",
        "report",
        "explain",
        "merge",
        "report MB"
    );
    for r in rows {
        let ratio = r.campaign.wall.as_secs_f64() / r.unrecorded.wall.as_secs_f64().max(1e-9);
        println!(
            "{:>7} {:>7} {:>11.1} {:>6.2} {:>8.3} |          {:>5} {:>5} {:>6} {:>7} {:>5} | {:>9.1}",
            r.tests,
            r.failing,
            r.campaign.wall.as_secs_f64(),
            ratio,
            r.mb_per_test,
            mb(&r.campaign),
            mb(&r.show),
            mb(&r.report),
            mb(&r.explain),
            mb(&r.merge),
            r.report_mb,
        );
    }
    println!();
    println!(
        "{:>7} | seconds: {:>11} {:>5} {:>6} {:>7} {:>5}",
        "tests", "unrecorded", "show", "report", "explain", "merge"
    );
    for r in rows {
        let s = |c: &Cost| c.wall.as_secs_f64();
        println!(
            "{:>7} |          {:>11.1} {:>5.1} {:>6.1} {:>7.1} {:>5.1}",
            r.tests,
            s(&r.unrecorded),
            s(&r.show),
            s(&r.report),
            s(&r.explain),
            s(&r.merge)
        );
    }
    println!();
    print_slope(
        &rows
            .iter()
            .map(|r| (r.tests, r.unrecorded.peak_mb))
            .collect::<Vec<_>>(),
    );
    println!(
        "×rec: the campaign's time with --record failing over its time with --record none; \
         MB/test: campaign.mcap (with --record failing, only the tests that did not pass are \
         in it) over all the tests"
    );
}

#[cfg(test)]
mod tests {
    use super::memory_slope;

    #[test]
    fn the_slope_is_what_each_test_adds_to_the_peak() {
        // 40 MB and 0.3 kB a test, with a size whose peak is unknown left out.
        let points = [
            (1_000, Some(40.3)),
            (10_000, Some(43.0)),
            (30_000, Some(49.0)),
            (50_000, None),
        ];
        let (base, kb) = memory_slope(&points).unwrap();
        assert!((base - 40.0).abs() < 1e-9, "{base}");
        assert!((kb - 0.3).abs() < 1e-9, "{kb}");
        assert_eq!(memory_slope(&points[..1]), None);
        assert_eq!(memory_slope(&[(5, Some(1.0)), (5, Some(2.0))]), None);
    }
}
