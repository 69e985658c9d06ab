//! `drivecheck compare BASE NEW`: two runs of the same tests compared, paired and noise-aware
//! (the method is `campaign::compare`'s, the words `docs/compare.md`'s).
//!
//! Both run directories are read a case file at a time; of each case only its small row
//! (`campaign::compare::TestRow`: a digest per command, a few numbers per segment) is kept, so
//! memory grows with tests and segments, never with whole cases. The summary, the JSON document
//! and the HTML page (`report::compare`) are written from the pairs and the comparison.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result, bail};
use serde::Serialize;

use crate::cli::{CompareArgs, FailOn};
use crate::exit::Exit;
use crate::output;
use campaign::compare::{
    BreakdownRow, Options, Paired, Report, Significance, TestRow, compare as compare_runs, p_words,
    pair,
};
use report::compare::{Compared, NoiseSource, noise_words, signed};
use report::data::{case_files, read_case, read_record};

/// The noise when neither `--noise` nor `--noise-from` is given, metres: a replay counts as the
/// same test when every segment's largest deviation is within 0.2 m of the other run's and its
/// verdict is the same (`docs/case-format.md`, *Where a fault acts over a slow link*). A
/// measurement of the simulated car's rerun noise may change it.
pub const DEFAULT_NOISE_M: f64 = 0.2;

/// The file the page is written to in NEW's run directory when `--report` names none.
pub const COMPARE_REPORT_FILE: &str = "compare.html";

/// Breakdown rows the summary shows per breakdown (the JSON and the page have every row).
const TOP_ROWS: usize = 5;

/// `drivecheck compare --json`'s document after `command` and `schema_version` (docs/json.md).
#[derive(Debug, Serialize)]
struct Document<'a> {
    base: String,
    new: String,
    noise: &'a NoiseSource,
    comparison: &'a Report,
}

/// The rows of every case file of the run directory `dir`, a case at a time.
pub fn read_rows(dir: &Path) -> Result<Vec<TestRow>> {
    if !dir.is_dir() {
        bail!("{}: no such run directory", dir.display());
    }
    read_record(dir)?;
    let mut rows = Vec::new();
    for (index, file) in case_files(dir)? {
        let case = read_case(dir, &file)?;
        // Nothing a case says is taken on trust, as `runs merge` takes none: an edited verdict,
        // statistics no deviations give, a segment's result repeated are refused, naming it.
        case.check()
            .with_context(|| dir.join(&file).display().to_string())?;
        if case.test_index != Some(index) {
            bail!(
                "{}: holds test {}, not test {index}",
                dir.join(&file).display(),
                case.test_index
                    .map_or_else(|| "none".to_owned(), |t| t.to_string())
            );
        }
        rows.push(TestRow::of(&case, index));
    }
    Ok(rows)
}

/// Pairs the runs of `base` and `new`, each a run directory's rows.
fn paired(
    base: Vec<TestRow>,
    new: Vec<TestRow>,
    base_dir: &Path,
    new_dir: &Path,
) -> Result<Paired> {
    pair(base, new).with_context(|| {
        format!(
            "{} and {} are not runs of the same tests",
            base_dir.display(),
            new_dir.display()
        )
    })
}

/// Reads and compares the run directories `base` and `new` (see the module doc). `noise_m`
/// (`--noise`) or `noise_from` (`--noise-from`) give the noise, else [`DEFAULT_NOISE_M`].
pub fn compare_dirs(
    base: &Path,
    new: &Path,
    noise_m: Option<f64>,
    noise_from: Option<&Path>,
    alpha: f64,
    seed: u64,
) -> Result<Compared> {
    let base_rows = read_rows(base)?;
    let scenario = read_record(base)?.scenario;
    let new_rows = read_rows(new)?;
    let (noise, noise_source) = match (noise_m, noise_from) {
        (Some(m), _) => (m, NoiseSource::Given),
        (None, Some(dir)) => {
            let rerun = paired(base_rows.clone(), read_rows(dir)?, base, dir)?;
            let segments = rerun.segments().filter(|s| s.change_m().is_some()).count();
            let noise = rerun.rerun_noise_m().with_context(|| {
                format!(
                    "--noise-from {}: no segment was measured in both it and BASE",
                    dir.display()
                )
            })?;
            (
                noise,
                NoiseSource::Rerun {
                    dir: dir.to_owned(),
                    segments,
                },
            )
        }
        (None, None) => (DEFAULT_NOISE_M, NoiseSource::Default),
    };
    let paired = paired(base_rows, new_rows, base, new)?;
    let options = Options {
        alpha,
        seed,
        ..Options::with_noise(noise)
    };
    let report = compare_runs(&paired, &options)?;
    Ok(Compared {
        base: base.to_owned(),
        scenario,
        new: new.to_owned(),
        noise_source,
        paired,
        report,
    })
}

/// Compares (see the module doc). Exit status 0; 1 with `--fail-on regression` when NEW is
/// significantly worse (or worse by one measure and better by the other); 2 on an error.
pub fn compare(args: &CompareArgs) -> Result<Exit> {
    let compared = compare_dirs(
        &args.base,
        &args.new,
        args.noise,
        args.noise_from.as_deref(),
        args.alpha,
        args.seed,
    )?;
    if let Some(file) = &args.report {
        let out = file
            .clone()
            .unwrap_or_else(|| args.new.join(COMPARE_REPORT_FILE));
        report::compare::write(&compared, &out)
            .with_context(|| format!("cannot write {}", out.display()))?;
        output::note(format_args!("wrote {}", out.display()));
    }
    if args.json {
        output::print_json(
            output::json::COMPARE,
            &Document {
                base: args.base.display().to_string(),
                new: args.new.display().to_string(),
                noise: &compared.noise_source,
                comparison: &compared.report,
            },
        )?;
    } else {
        print!("{}", summary(&compared));
    }
    let worse = matches!(
        compared.report.significance,
        Significance::Worse | Significance::Mixed
    );
    Ok(match args.fail_on {
        Some(FailOn::Regression) if worse => Exit::Found,
        _ => Exit::Success,
    })
}

fn percent(part: usize, whole: usize) -> String {
    if whole == 0 {
        "–".to_owned()
    } else {
        format!("{:.1} %", 100.0 * part as f64 / whole as f64)
    }
}

/// The text summary: the verdict, the tests' table, the statistics and the top breakdown rows.
pub fn summary(compared: &Compared) -> String {
    let r = &compared.report;
    let t = &r.tests;
    let s = &r.segments;
    let mut out = String::new();
    let _ = writeln!(out, "{}\n", r.verdict);
    let _ = writeln!(out, "BASE  {}", compared.base.display());
    let _ = writeln!(out, "NEW   {}\n", compared.new.display());
    let _ = writeln!(
        out,
        "{:<14}{:>12}{:>12}",
        "tests", "NEW passed", "NEW failed"
    );
    let _ = writeln!(
        out,
        "{:<14}{:>12}{:>12}",
        "BASE passed", t.both_passed, t.regressed
    );
    let _ = writeln!(
        out,
        "{:<14}{:>12}{:>12}",
        "BASE failed", t.fixed, t.both_failed
    );
    let _ = writeln!(
        out,
        "({} tests in both; failed includes aborted)\n",
        t.paired
    );
    let _ = writeln!(
        out,
        "segments: {} driven in both ({} measured), {} only in BASE, {} only in NEW",
        s.paired, s.measured, s.only_base, s.only_new
    );
    let _ = writeln!(out, "  noise: {}", noise_words(compared));
    let _ = writeln!(
        out,
        "  worse by more than the noise: {} ({}), better: {} ({})",
        s.worse,
        percent(s.worse, s.measured),
        s.better,
        percent(s.better, s.measured)
    );
    let _ = writeln!(
        out,
        "  segment verdicts: {} regressed, {} fixed",
        s.regressed, s.fixed
    );
    let _ = writeln!(
        out,
        "McNemar (tests' verdicts): {} regressed, {} fixed, two-sided p = {} (significant below {})",
        r.mcnemar.regressed,
        r.mcnemar.fixed,
        p_words(r.mcnemar.p),
        r.alpha / 2.0
    );
    match &r.median_change {
        None => {
            let _ = writeln!(out, "median change: no segment measured in both runs");
        }
        Some(m) => {
            let _ = writeln!(
                out,
                "median change of a segment's largest deviation: {} m, 95 % CI {} to {} m \
                 ({} bootstrap resamples); sign-flip p = {} (significant below {}; {} sign \
                 assignments of {} tests, seed {})",
                signed(Some(m.median_m)),
                signed(Some(m.ci95_m[0])),
                signed(Some(m.ci95_m[1])),
                m.resamples,
                p_words(m.p),
                r.alpha / 2.0,
                m.flips,
                m.tests,
                m.seed
            );
        }
    }
    // Each breakdown's rows are in the order of blame (docs/compare.md), not of their keys.
    let _ = writeln!(
        out,
        "\nbreakdowns, the group that explains most of the regression first:"
    );
    for (what, rows) in [
        ("fault", &r.breakdowns.by_fault),
        ("speed", &r.breakdowns.by_speed),
        ("region", &r.breakdowns.by_region),
    ] {
        breakdown_table(&mut out, what, rows);
    }
    out
}

fn breakdown_table(out: &mut String, what: &str, rows: &[BreakdownRow]) {
    let shown = rows.len().min(TOP_ROWS);
    let title = if rows.len() > shown {
        format!("by {what} (top {shown} of {})", rows.len())
    } else {
        format!("by {what}")
    };
    let width = rows
        .iter()
        .take(shown)
        .map(|r| r.key.chars().count())
        .chain([title.chars().count()])
        .max()
        .unwrap_or(0);
    let _ = writeln!(
        out,
        "\n{title:<width$}  segments  median Δ  worse  better  regressed  fixed"
    );
    for r in rows.iter().take(shown) {
        let pad = width - r.key.chars().count();
        let _ = writeln!(
            out,
            "{}{}  {:>8}  {:>7}  {:>5}  {:>6}  {:>9}  {:>5}",
            r.key,
            " ".repeat(pad),
            r.segments,
            signed(r.median_change_m),
            r.worse,
            r.better,
            r.regressed,
            r.fixed
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use campaign::compare::{FaultKey, PairedSegment, PairedTest};
    use campaign::files::ScenarioRef;
    use campaign::model::{FaultKind, Probe};
    use campaign::oracle::{SegmentVerdict, Verdict};
    use std::path::PathBuf;

    /// 24 tests; NEW is worse on segments under a range offset on anchor 50.
    fn example() -> Compared {
        let range = FaultKey {
            probe: Probe::UwbRange(50),
            kind: FaultKind::Offset,
        };
        let yaw = FaultKey {
            probe: Probe::UwbYaw,
            kind: FaultKind::Amplification,
        };
        let judge = |m: f64| {
            if m <= 1.0 {
                SegmentVerdict::Passed
            } else {
                SegmentVerdict::Failed
            }
        };
        let tests = (0..24)
            .map(|t| {
                let segments: Vec<PairedSegment> = (0..4)
                    .map(|i| {
                        let base = 0.3 + 0.05 * ((t * 5 + i) % 7) as f64;
                        let faults = match i {
                            1 => vec![range],
                            2 => vec![yaw],
                            _ => vec![],
                        };
                        let shift = match i {
                            1 => 0.45 + 0.02 * (t % 3) as f64,
                            2 => 0.25,
                            _ => 0.0,
                        };
                        let new = base + shift + 0.01 * ((t + i) % 3) as f64 - 0.01;
                        PairedSegment {
                            test_index: t,
                            segment_index: i,
                            base_verdict: judge(base),
                            new_verdict: judge(new),
                            base_max_m: Some(base),
                            new_max_m: Some(new),
                            faults,
                            speed_mps: Some(0.8 + 0.6 * i as f64),
                            route: vec![
                                [-12.0 + t as f64, -4.0 + 3.0 * i as f64],
                                [-11.0 + t as f64, -3.0 + 3.0 * i as f64],
                            ],
                        }
                    })
                    .collect();
                let verdict = |new: bool| {
                    let ok = segments.iter().all(|s| {
                        (if new { s.new_verdict } else { s.base_verdict }) == SegmentVerdict::Passed
                    });
                    Some(if ok { Verdict::Passed } else { Verdict::Failed })
                };
                PairedTest {
                    test_index: t,
                    base_verdict: verdict(false),
                    new_verdict: verdict(true),
                    segments,
                    only_base: usize::from(t == 3),
                    only_new: 0,
                }
            })
            .collect();
        let paired = Paired { tests };
        let report = compare_runs(&paired, &Options::with_noise(DEFAULT_NOISE_M)).unwrap();
        Compared {
            base: PathBuf::from("runs/base"),
            scenario: ScenarioRef {
                name: "parking-lot-2anchors".to_owned(),
                hash: None,
            },
            new: PathBuf::from("runs/new"),
            noise_source: NoiseSource::Default,
            paired,
            report,
        }
    }

    #[test]
    fn the_summary_reads_as_a_user_reads_it() {
        let compared = example();
        assert_eq!(compared.report.significance, Significance::Worse);
        insta::assert_snapshot!("compare_summary", summary(&compared));
    }

    #[test]
    fn the_json_document_has_the_comparison() {
        let compared = example();
        let value = serde_json::to_value(Document {
            base: "a".into(),
            new: "b".into(),
            noise: &compared.noise_source,
            comparison: &compared.report,
        })
        .unwrap();
        assert_eq!(value["noise"]["from"], "default");
        assert_eq!(value["comparison"]["significance"], "worse");
        assert_eq!(
            value["comparison"]["breakdowns"]["by_fault"][0]["key"],
            "uwb_range_50 offset"
        );
        assert_eq!(value["comparison"]["evidence"]["deviation_worse"], true);
    }
}
