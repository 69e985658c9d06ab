//! The command line of `drivecheck-dev`.

use std::ffi::OsString;
use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// drivecheck's development tools: benchmarks of its own speed and fidelity, and `exec`, a
/// `drivecheck` command run in this process.
#[derive(Debug, Parser)]
#[command(name = "drivecheck-dev", version, about, max_term_width = 100)]
pub struct DevCli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Measure drivecheck's own speed and its simulated car's fidelity (run with `cargo run
    /// --release -p drivecheck-dev`). Exit status: 0 measured, 2 error.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Run a `drivecheck` command in this process, as the `drivecheck` binary would
    /// (`drivecheck-dev exec run --tests 10`); with `DRIVECHECK_PEAK_MEMORY_FILE` set, the
    /// process's peak resident set (kB) is written to that file as it ends. Exit status: the
    /// command's.
    Exec(ExecArgs),
}

/// Options of `drivecheck-dev exec`.
#[derive(Debug, Args)]
pub struct ExecArgs {
    /// The `drivecheck` command line, without the program's name.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, required = true)]
    pub args: Vec<OsString>,
}

/// `drivecheck-dev bench …`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Both generator strategies side by side on every bundled area: time per extension
    /// (p50/p99/max), outer tries, failures, and the wall time of an area validation. Exit
    /// status: 0 measured, 2 error.
    Generator(BenchGeneratorArgs),
    /// Both return-route planners side by side on every bundled area, from random poses with
    /// at least 1 m clearance: success, plan time p50/p99, length and ratio to the lower bound.
    /// Exit status: 0 measured, 2 error.
    Recovery(BenchRecoveryArgs),
    /// The simulated car's fault effects next to the published real-car experiments: the
    /// published fault sequence on generated tests of `parking-lot-august` (with and without its
    /// faults, and rerun with other simulator seeds), and the rock lot without faults. Exit
    /// status: 0 measured, 2 error.
    Fidelity(BenchFidelityArgs),
    /// How close to its place on the route each fault is added over a slow, jittery link:
    /// campaigns in virtual time on simulated cars behind the simulator's impaired link, per
    /// firmware generation, the distribution of the placement errors. Exit status: 0 measured,
    /// 2 error.
    Placement(BenchPlacementArgs),
    /// What a campaign and every reader of its run directory cost as the campaign grows:
    /// campaigns of each size (`--record failing`, and unrecorded for the time), then `runs show`,
    /// `report`, `explain` and `runs merge` of two shards, each a `drivecheck` process of its own:
    /// wall time, peak memory (RSS), recording bytes per test, report size. Exit status: 0
    /// measured, 2 error.
    Scale(BenchScaleArgs),
    /// How `drivecheck compare` decides, measured on the simulated car: the same cases driven in
    /// pairs of runs on the same car with other seeds (false alarms, and the noise of a
    /// segment's largest deviation), and on degraded cars (how often the regression is found,
    /// by number of tests), and firmware 10.1 against 12.3. Exit status: 0 measured, 2 error.
    Compare(BenchCompareArgs),
    /// A campaign killed (`kill -9`) at random moments and resumed each time, against the
    /// uninterrupted run: how often its case files, summary and recording messages are the
    /// same. Exit status: 0 every resumed campaign the uninterrupted one, 1 one is not, 2 error.
    KillResume(BenchKillResumeArgs),
    /// The simulated car's model of the firmware against the car's own firmware built for the
    /// host: for every tree and seed, the same campaign on `--car sitl:TREE` and on `--car sim`
    /// with the profile of the tree's version; verdicts agreed test by test and Δ of each
    /// segment's largest deviation (`docs/sitl.md`, *In a campaign*). Exit status: 0 measured, 2
    /// error.
    Agreement(BenchAgreementArgs),
    /// How near `drivecheck calibrate` brings the twin to what the recordings allow (#54):
    /// held-out cars written as profiles, each driven as "the car" for a training campaign whose
    /// run directory is stripped of every `/sim/*` channel and of the profile, calibrated on,
    /// then `twin check` of a held-out campaign of another seed on the fitted profile, the
    /// default and the car's own profile (the ceiling); the fitted parameters' errors. Exit
    /// status: 0 measured, 2 error.
    TwinReach(BenchTwinReachArgs),
}

/// Options of `drivecheck-dev bench agreement`.
#[derive(Debug, Args)]
pub struct BenchAgreementArgs {
    /// A firmware tree (`.../Embedded/RC_Controller`); give it once per tree.
    #[arg(long = "tree", value_name = "DIR", required = true)]
    pub trees: Vec<PathBuf>,
    /// Campaign seeds (from `--seed` on).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub seeds: u32,
    /// Tests per campaign.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Tests at once in each campaign.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub jobs: u32,
    /// Scenario: a bundled name or a file.
    #[arg(long, default_value = "parking-lot-2anchors")]
    pub scenario: String,
    /// Where the run directories go (a new directory; default: a scratch directory removed at
    /// the end).
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
    /// Drive the campaigns with this `drivecheck` binary (`EXE -q run …`) instead of this
    /// process's own (`drivecheck-dev exec`): another build's figures, e.g. before a change.
    #[arg(long, value_name = "EXE")]
    pub drivecheck: Option<PathBuf>,
}

/// Options of `drivecheck-dev bench twin-reach`.
#[derive(Debug, Args)]
pub struct BenchTwinReachArgs {
    /// Only these cars (their letters, `F,G`); default: every car of the bench.
    #[arg(long, value_delimiter = ',')]
    pub cars: Vec<String>,
    /// Tests of the campaign calibrated on.
    #[arg(long, default_value_t = 40, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// Its seed.
    #[arg(long, default_value_t = 21)]
    pub seed: u64,
    /// Tests of the held-out campaign the fit is checked on.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub held_tests: u32,
    /// Its seed.
    #[arg(long, default_value_t = 22)]
    pub held_seed: u64,
    /// `twin check --runs`.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub runs: u32,
    /// Passed on to `calibrate` (`--budget`, `--jobs`, `--restarts`…), one word each:
    /// `--calibrate=--budget,5min`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub calibrate: Vec<String>,
    /// Where the run directories and profiles go (a new directory, kept; default: a scratch
    /// directory removed at the end).
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
}

/// Options of `drivecheck-dev bench kill-resume`.
#[derive(Debug, Args)]
pub struct BenchKillResumeArgs {
    /// Tests of the campaign.
    #[arg(long, default_value_t = 30, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=10_000))]
    pub tests: usize,
    /// How many times it is killed and resumed (each time from the start, in a directory of
    /// its own).
    #[arg(long, default_value_t = 50, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=10_000))]
    pub kills: usize,
    /// The campaign's seed (and of the moments of the kills).
    #[arg(long, default_value_t = 3)]
    pub seed: u64,
    /// Tests at once.
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    pub jobs: usize,
    /// Where the run directories go (kept; default: a scratch directory removed at the end).
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
}

/// Options of `drivecheck-dev bench compare`.
#[derive(Debug, Args)]
pub struct BenchCompareArgs {
    /// Tests of the cases every run drives (the power table also compares their first quarter
    /// and half).
    #[arg(long, default_value_t = 200, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(4..=100_000))]
    pub tests: usize,
    /// Pairs of runs on the same car (false alarms), and of runs on each degraded car.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub pairs: u32,
    /// The cases' seed; run k drives them with seed SEED + k.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The car: `sim` (the embedded simulated car and its degraded profiles) or `sitl:TREE`,
    /// the car's own firmware built from TREE (BASE) and degraded copies of it: the firmware
    /// regression gate of docs/sitl.md.
    #[arg(long, default_value = "sim", value_name = "sim|sitl:TREE")]
    pub car: String,
    /// With `--car sitl:TREE`: a candidate firmware tree of your own, judged as the degraded
    /// copies are (how often the gate finds it worse than TREE).
    #[arg(long, value_name = "TREE")]
    pub candidate: Option<PathBuf>,
    /// Where the run directories go (a new directory; default: a scratch directory removed at
    /// the end).
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
}

/// Options of `drivecheck-dev bench scale`.
#[derive(Debug, Args)]
pub struct BenchScaleArgs {
    /// Campaign sizes, in tests.
    #[arg(long, value_delimiter = ',', default_value = "100,1000,10000",
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1_000_000))]
    pub sizes: Vec<usize>,
    /// Tests run at once in each campaign and shard.
    #[arg(long, default_value_t = 2, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    pub jobs: usize,
    /// The campaigns' seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where the run directories go (a new directory; default: a scratch directory removed at
    /// the end).
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
    /// Only the campaign with `--record none` (its time and peak memory) at each size, no
    /// recording and no reader: the memory a campaign keeps per test, at sizes where the rest
    /// would take hours.
    #[arg(long)]
    pub unrecorded_only: bool,
}

/// Options of `drivecheck-dev bench placement`.
#[derive(Debug, Args)]
pub struct BenchPlacementArgs {
    /// Scenario: a bundled name, a .toml, a reference .xml or a .geojson file.
    #[arg(long, default_value = "parking-lot-2anchors")]
    pub scenario: String,
    /// Campaign seeds (from `--seed` on).
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub seeds: u32,
    /// Link seeds per campaign seed (other jitter draws, other sensor noise).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub link_seeds: u32,
    /// Tests per campaign.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// The link's added one-way latency.
    #[arg(long, default_value = "150ms", value_parser = humantime::parse_duration)]
    pub link_latency: std::time::Duration,
    /// Extra one-way delay drawn uniformly from 0 to this.
    #[arg(long, default_value = "40ms", value_parser = humantime::parse_duration)]
    pub link_jitter: std::time::Duration,
    /// Firmware generation: 10.1, 12.3 or both.
    #[arg(long, default_value = "both")]
    pub firmware: String,
    /// The first campaign seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Options of `drivecheck-dev bench fidelity`.
#[derive(Debug, Args)]
pub struct BenchFidelityArgs {
    /// The lot of the published fault sequence: `parking-lot-august` or a variant of it (a .toml
    /// file), for example with other speeds.
    #[arg(long, default_value = "parking-lot-august")]
    pub scenario: String,
    /// Generated tests of the published fault sequence (one per seed).
    #[arg(long, default_value_t = 40, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// Runs of each test with its faults, with other simulator seeds (the reruns' spread).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub reruns: u32,
    /// Tests of the rock lot's campaign without faults.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub rock_tests: u32,
    /// Also draw where the rock lot's campaign failed as SVG to FILE: every driven track, the
    /// samples above 1 m, the rock and the wall (`--svg` is an older name of this option).
    #[arg(short = 'o', long = "out", alias = "svg", value_name = "FILE.svg")]
    pub svg: Option<PathBuf>,
    /// Simulated runs of the published circle route (route following, other simulator seeds).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub route_runs: u32,
    /// Only fit the simulated GNSS noise to the real car's circle route: every σ and correlation
    /// time of a grid, with `--route-runs` runs each (how `GnssModel::default()` was chosen).
    #[arg(long, hide = true)]
    pub fit_gnss: bool,
    /// The car profile of every simulated car: `default` or a TOML file (docs/twin.md); its
    /// anchors must be the lots' (the route following leaves them out).
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// The car: `sim`, the embedded simulated car, or `sitl:TREE`, the car's own firmware built
    /// from TREE for the host in the same physical car (the fault sequence and the rock lot; the
    /// route following stays on `sim`).
    #[arg(long, default_value = "sim", value_name = "sim|sitl:TREE")]
    pub car: String,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Options of `drivecheck-dev bench recovery`.
#[derive(Debug, Args)]
pub struct BenchRecoveryArgs {
    /// Random poses per area.
    #[arg(long, default_value_t = 200)]
    pub poses: usize,
    /// Least distance of a pose from every edge, metres.
    #[arg(long, default_value_t = 1.0)]
    pub clearance: f64,
    /// Seed of the poses and of the planners.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Options of `drivecheck-dev bench generator`.
#[derive(Debug, Args)]
pub struct BenchGeneratorArgs {
    /// Extensions (4–7 points plus the ahead margin) measured per area and strategy.
    #[arg(long, default_value_t = 2000)]
    pub extensions: usize,
    /// Length of the validation run per area and strategy, kilometres.
    #[arg(long, default_value_t = 100.0)]
    pub km: f64,
    /// Seed of the random routes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Distance every route keeps from every edge, metres, instead of each scenario's own
    /// (0.5 m in the bundled ones; 0 compares with the reference's published figures, which
    /// kept none).
    #[arg(long, value_name = "METRES")]
    pub clearance: Option<f64>,
}
