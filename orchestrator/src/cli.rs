//! The command line: every `drivecheck` subcommand and its options.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// drivecheck tests a vehicle by driving it: random drivable trajectories in a test area, faults
/// injected into UWB positioning, UWB checked against RTK.
#[derive(Debug, Parser)]
#[command(name = "drivecheck", version, about, max_term_width = 100)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Check a test area before any car drives in it.
    #[command(subcommand)]
    Area(AreaCommand),
    /// Generate routes in a test area.
    #[command(subcommand)]
    Route(RouteCommand),
    /// Read, check and convert scenario files.
    #[command(subcommand)]
    Scenario(ScenarioCommand),
    /// Measure drivecheck's own speed (run with `cargo run --release`).
    #[command(subcommand)]
    Bench(BenchCommand),
}

/// `drivecheck bench …`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Both generator strategies side by side on every bundled area: time per extension
    /// (p50/p99/max), outer tries, failures, and the wall time of an area validation.
    Generator(BenchGeneratorArgs),
    /// Both return-route planners side by side on every bundled area, from random poses with
    /// at least 1 m clearance: success, plan time p50/p99, length and ratio to the lower bound.
    Recovery(BenchRecoveryArgs),
}

/// Options of `drivecheck bench recovery`.
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

/// Options of `drivecheck bench generator`.
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
}

/// `drivecheck area …`
#[derive(Debug, Subcommand)]
pub enum AreaCommand {
    /// Drive one long generated trajectory through the area and give a verdict (method §4).
    ///
    /// The area is `safe` when no extension failed and no extension needed more than half the
    /// generator's outer tries. Exit status: 0 safe, 1 unsafe, 2 error.
    Validate(ValidateArgs),
}

/// Options of `drivecheck area validate`.
#[derive(Debug, Args)]
pub struct ValidateArgs {
    /// Scenario: a bundled name (see `drivecheck scenario list`), a .toml file or a reference .xml.
    pub scenario: String,
    /// Length of the trajectory, kilometres.
    #[arg(long, default_value_t = 100.0)]
    pub km: f64,
    /// Seed of the random trajectory (printed when not given).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Write a picture (area, trajectory sample, coverage heat map, hot spots) to this SVG file.
    #[arg(long, value_name = "FILE")]
    pub svg: Option<PathBuf>,
    /// Print the report as JSON on standard output.
    #[arg(long)]
    pub json: bool,
    /// Generator strategy.
    #[arg(long, value_enum, default_value_t = StrategyArg::Wedge)]
    pub strategy: StrategyArg,
}

/// `drivecheck route …`
#[derive(Debug, Subcommand)]
pub enum RouteCommand {
    /// Extend the scenario's start route by N points, in extensions of the scenario's segment
    /// size (4–7 points by default), each proven drivable by the ahead margin.
    Generate(GenerateArgs),
    /// Plan the return route from a pose to the scenario's recovery route (what the car drives
    /// between tests), with its length, a lower bound and their ratio.
    Return(ReturnArgs),
}

/// Options of `drivecheck route return`.
#[derive(Debug, Args)]
pub struct ReturnArgs {
    /// Scenario: a bundled name, a .toml file or a reference .xml.
    pub scenario: String,
    /// The car's pose: east and north in metres, and the heading in degrees counter-clockwise
    /// from east (the ENU convention: 0 = east, 90 = north).
    #[arg(long, value_name = "X,Y,HEADING_DEG", allow_hyphen_values = true)]
    pub from: String,
    /// Seed of the planner's random choices (printed when not given).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Planner: `dubins` (search over poses with Dubins connections, the default) or
    /// `reference` (the method's arcs, random extensions and best of 100).
    #[arg(long, default_value = "dubins")]
    pub planner: recovery::Planner,
    /// Print the route as JSON on standard output.
    #[arg(long)]
    pub json: bool,
}

/// Options of `drivecheck route generate`.
#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Scenario: a bundled name, a .toml file or a reference .xml.
    pub scenario: String,
    /// How many points to generate after the start route.
    #[arg(long)]
    pub points: usize,
    /// Seed of the random route (printed when not given).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Speed of the generated points, m/s (default: the scenario's lowest campaign speed).
    #[arg(long, value_name = "M/S")]
    pub speed: Option<f64>,
    /// Print the route as JSON on standard output.
    #[arg(long)]
    pub json: bool,
    /// Generator strategy.
    #[arg(long, value_enum, default_value_t = StrategyArg::Wedge)]
    pub strategy: StrategyArg,
}

/// `drivecheck scenario …`
#[derive(Debug, Subcommand)]
pub enum ScenarioCommand {
    /// Convert a reference route XML file into a scenario TOML file.
    Import(ImportArgs),
    /// Load and validate a scenario; print its warnings. Exit status: 0 valid, 2 invalid.
    Check(CheckArgs),
    /// List the bundled scenarios.
    List,
}

/// Options of `drivecheck scenario import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The reference XML file.
    pub xml: PathBuf,
    /// Where to write the scenario TOML (standard output when not given).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

/// Options of `drivecheck scenario check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Scenario: a bundled name, a .toml file or a reference .xml.
    pub scenario: String,
}

/// The generator's strategy, as named on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StrategyArg {
    /// Sampling in the turn wedge with backtracking (drivecheck's default).
    Wedge,
    /// The reference implementation's box sampling with restarts (for comparison).
    Reference,
}

impl From<StrategyArg> for trajgen::Strategy {
    fn from(arg: StrategyArg) -> Self {
        match arg {
            StrategyArg::Wedge => trajgen::Strategy::Wedge,
            StrategyArg::Reference => trajgen::Strategy::Reference,
        }
    }
}
