//! `drivecheck-dev bench agreement`: how close the embedded simulated car's model of the firmware
//! is to the car's own firmware built for the host (`docs/sitl.md`, *In a campaign*: the
//! agreement table).
//!
//! For every tree and every seed, one campaign on the firmware (`run --car sitl:TREE --seed S
//! --tests N`) and one on the simulated car with the profile of the tree's firmware version
//! (`firmware = "X.Y"`, read from the firmware run's `campaign.json`), both in virtual time, each a
//! `drivecheck` process of its own (`drivecheck-dev exec`). Test by test: the verdicts agreed;
//! segment by segment (the same index in the same test): Δ of the largest deviation, firmware −
//! model. The plant of test *i* is seeded as the simulated car of test *i*, so a difference is
//! a difference of firmware (up to what the plant cannot share with the simulated car).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use campaign::compare::{TestRow, nearest_rank};
use orchestrator::commands::compare::read_rows;
use orchestrator::commands::scratch::Scratch;
use orchestrator::exit::Exit;

use crate::cli::BenchAgreementArgs;

/// What one tree gave over every seed.
#[derive(Debug, Default)]
pub struct Agreement {
    /// The tree's firmware version, as its campaign recorded it.
    pub version: String,
    /// Tests run on both cars.
    pub tests: usize,
    /// Of those, with the same verdict.
    pub agreed: usize,
    /// Every segment measured on both: firmware's largest deviation − the model's, metres.
    pub deltas: Vec<f64>,
    /// The tests whose verdicts differ: (seed, test index, firmware's, model's).
    pub disagreements: Vec<(u64, usize, String, String)>,
    /// Wall time of the firmware's campaigns and of the simulated car's, seconds.
    pub wall_s: (f64, f64),
}

impl Agreement {
    /// Median |Δ|, metres.
    pub fn median_abs(&self) -> f64 {
        self.abs_quantile(0.5)
    }

    /// The `q` quantile (nearest rank) of |Δ|, metres (NaN without a segment).
    pub fn abs_quantile(&self, q: f64) -> f64 {
        let mut abs: Vec<f64> = self.deltas.iter().map(|d| d.abs()).collect();
        abs.sort_by(f64::total_cmp);
        nearest_rank(&abs, q).unwrap_or(f64::NAN)
    }

    /// Mean Δ (firmware − model), metres.
    pub fn mean(&self) -> f64 {
        self.deltas.iter().sum::<f64>() / self.deltas.len().max(1) as f64
    }

    /// Adds one seed's campaigns, paired test by test and segment by segment.
    fn add(&mut self, seed: u64, firmware: &[TestRow], model: &[TestRow]) {
        for f in firmware {
            let Some(m) = model.iter().find(|m| m.test_index == f.test_index) else {
                continue;
            };
            self.tests += 1;
            if f.verdict == m.verdict {
                self.agreed += 1;
            } else {
                self.disagreements
                    .push((seed, f.test_index, verdict_name(f), verdict_name(m)));
            }
            for fs in &f.segments {
                let Some(ms) = m
                    .segments
                    .iter()
                    .find(|s| s.segment_index == fs.segment_index)
                else {
                    continue;
                };
                if let (Some(a), Some(b)) = (fs.max_m, ms.max_m) {
                    self.deltas.push(a - b);
                }
            }
        }
    }
}

fn verdict_name(row: &TestRow) -> String {
    row.verdict
        .map_or_else(|| "-".to_owned(), |v| format!("{v:?}").to_lowercase())
}

/// Measures and prints the table.
pub fn run(args: &BenchAgreementArgs) -> Result<Exit> {
    let exe = match &args.drivecheck {
        Some(exe) => Drivecheck::Binary(exe.clone()),
        None => Drivecheck::Exec(
            std::env::current_exe().context("cannot find the drivecheck-dev executable")?,
        ),
    };
    let (_scratch, root) = Scratch::given_or_new(args.scratch.as_deref(), "bench", "agreement")?;
    println!(
        "bench agreement: {} seeds from {} × {} tests on {}, each tree's firmware against the \
         simulated car with its version's profile (virtual time, --jobs {})\n",
        args.seeds, args.seed, args.tests, args.scenario, args.jobs
    );
    let mut results = Vec::new();
    for (t, tree) in args.trees.iter().enumerate() {
        let tree_text = tree
            .to_str()
            .with_context(|| format!("{}: not a UTF-8 path", tree.display()))?;
        let mut agreement = Agreement::default();
        for seed in args.seed..args.seed + u64::from(args.seeds) {
            let dir = root.join(format!("tree-{t}-seed-{seed}"));
            let (firmware_dir, model_dir) = (dir.join("firmware"), dir.join("model"));
            let seed_text = seed.to_string();
            let tests = args.tests.to_string();
            let jobs = args.jobs.to_string();
            let common = [
                "--seed",
                &seed_text,
                "--tests",
                &tests,
                "--jobs",
                &jobs,
                "--scenario",
                &args.scenario,
            ];
            let car = format!("sitl:{tree_text}");
            let started = Instant::now();
            drive(&exe, &common, &["--car", &car], &firmware_dir)?;
            agreement.wall_s.0 += started.elapsed().as_secs_f64();
            let record: serde_json::Value = serde_json::from_str(
                &std::fs::read_to_string(firmware_dir.join("campaign.json"))
                    .with_context(|| format!("cannot read {}", firmware_dir.display()))?,
            )
            .context("campaign.json")?;
            let version = record["car_firmware_version"]
                .as_str()
                .context("the firmware's campaign.json names no car_firmware_version")?
                .to_owned();
            let profile = dir.join("profile.toml");
            std::fs::write(
                &profile,
                format!(
                    "format = \"drivecheck-car-profile\"\nversion = 1\nfirmware = \"{version}\"\n"
                ),
            )
            .with_context(|| format!("cannot write {}", profile.display()))?;
            let started = Instant::now();
            drive(
                &exe,
                &common,
                &["--car", "sim", "--profile", path(&profile)?],
                &model_dir,
            )?;
            agreement.wall_s.1 += started.elapsed().as_secs_f64();
            agreement.add(seed, &read_rows(&firmware_dir)?, &read_rows(&model_dir)?);
            agreement.version = version;
        }
        results.push((tree.clone(), agreement));
    }
    println!(
        "| tree | verdicts agreed | median |Δ| of a segment's largest deviation | p90 |Δ| | mean Δ \
         (firmware − model) | segments |"
    );
    println!("|---|---|---|---|---|---|");
    for (tree, a) in &results {
        println!(
            "| {} ({}) | {} / {} | {:.3} m | {:.3} m | {:+.3} m | {} |",
            a.version,
            tree_name(tree),
            a.agreed,
            a.tests,
            a.median_abs(),
            a.abs_quantile(0.9),
            a.mean(),
            a.deltas.len()
        );
    }
    for (tree, a) in &results {
        println!(
            "\n{} ({}): wall {:.1} s on the firmware, {:.1} s on the simulated car; verdicts \
             that differ (seed, test: firmware / model): {}",
            a.version,
            tree_name(tree),
            a.wall_s.0,
            a.wall_s.1,
            if a.disagreements.is_empty() {
                "none".to_owned()
            } else {
                a.disagreements
                    .iter()
                    .map(|(s, i, f, m)| format!("{s}:{i} {f}/{m}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        );
    }
    Ok(Exit::Success)
}

/// The tree's name as a user knows it: the folder above `Embedded/RC_Controller` when it is one.
fn tree_name(tree: &Path) -> String {
    let parts: Vec<_> = tree.components().collect();
    let n = parts.len();
    let name = |c: &std::path::Component| c.as_os_str().to_string_lossy().into_owned();
    if n >= 3 && name(&parts[n - 1]) == "RC_Controller" && name(&parts[n - 2]) == "Embedded" {
        name(&parts[n - 3])
    } else {
        tree.display().to_string()
    }
}

/// The `drivecheck` that drives the campaigns.
enum Drivecheck {
    /// This process's executable, `drivecheck-dev exec`.
    Exec(PathBuf),
    /// A `drivecheck` binary.
    Binary(PathBuf),
}

/// `drivecheck -q run COMMON CAR --record none --out OUT`, its output discarded; it must end
/// with 0 or 1.
fn drive(exe: &Drivecheck, common: &[&str], car: &[&str], out: &PathBuf) -> Result<()> {
    let mut command = match exe {
        Drivecheck::Exec(path) => {
            let mut c = Command::new(path);
            c.arg("exec");
            c
        }
        Drivecheck::Binary(path) => Command::new(path),
    };
    let (Drivecheck::Exec(path) | Drivecheck::Binary(path)) = exe;
    let output = command
        .args(["-q", "run"])
        .args(common)
        .args(car)
        .args(["--record", "none", "--out"])
        .arg(out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .with_context(|| format!("cannot start {}", path.display()))?;
    match output.status.code() {
        Some(0 | 1) => Ok(()),
        _ => bail!(
            "drivecheck run {} {} ended with {}: {}",
            common.join(" "),
            car.join(" "),
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        ),
    }
}

fn path(p: &Path) -> Result<&str> {
    p.to_str()
        .with_context(|| format!("{}: not a UTF-8 path", p.display()))
}
