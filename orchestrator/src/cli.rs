//! The command line: every `drivecheck` subcommand and its options.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// drivecheck tests a vehicle by driving it: random drivable trajectories in a test area, faults
/// injected into UWB positioning, UWB checked against RTK.
#[derive(Debug, Parser)]
#[command(
    name = "drivecheck",
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("DRIVECHECK_REVISION"), ")"),
    about,
    max_term_width = 100,
    after_help = crate::exit::Exit::help()
)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
    /// Print only the result and errors: no progress, notes or warnings. A safety warning (a car
    /// left with fault injection enabled, what Ctrl-C does) prints even so. What each command
    /// leaves out: its --help.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Print more: what is the same on every run (a bundled scenario's drawing warnings) and, of
    /// a campaign, every test. What each command adds: its --help.
    #[arg(short, long, global = true)]
    pub verbose: bool,
}

/// `-v` of a command that reads a scenario and prints nothing more with it.
const VERBOSE_BUNDLED: &str = "Print the bundled scenario's drawing warnings too (about data you \
    cannot change, the same on every run: without -v only a scenario file's are printed).";

/// What `-q` and `-v` do for each command, as its `--help` says: the command (as typed), then
/// `-q`'s help and `-v`'s. `None`: the option does nothing for the command and is not offered
/// (its --help and the completions leave it out), though taken. What is printed at which
/// verbosity is decided in [`crate::output`]; `quiet_everywhere` (orchestrator/tests) runs every
/// command with `-q`.
pub const VERBOSITY: &[(&str, Option<&str>, Option<&str>)] = &[
    (
        "run",
        Some(
            "Print only the summary (no table of tests, no explanations) and errors: no \
             progress, notes or warnings. A safety warning (a car left with fault injection \
             enabled, what Ctrl-C does) prints even so.",
        ),
        Some(
            "Print more: a line and a table row for every test of a large campaign, every \
             failing case and explanation, the fields preflight switches off on the simulated \
             car, the bundled scenario's drawing warnings.",
        ),
    ),
    (
        "replay",
        Some(
            "Print only the comparison and errors: no progress (`replaying …`, a line per run), \
             notes or warnings. A safety warning (a car left with fault injection enabled, what \
             Ctrl-C does) prints even so.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "shrink",
        Some(
            "Print only the result and errors: no progress, notes or warnings (why a case is \
             not shrunk still prints).",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "sweep",
        Some(
            "Print only the table and errors: no progress (`sweeping …`, a line per value) or \
             warnings.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    ("runs", None, None),
    (
        "runs show",
        Some("Print only a campaign's summary (no table of tests) and errors."),
        Some("List every test in the table and every failing case, however many."),
    ),
    (
        "runs merge",
        Some(
            "Print only the result and errors: no notes (with --json, the merge's lines on \
             standard error; where --junit wrote).",
        ),
        None,
    ),
    (
        "report",
        Some("Print only errors: not where the report was written."),
        Some("Print the drawing warnings of a bundled --scenario too."),
    ),
    (
        "explain",
        Some(
            "Print only the explanations and errors: no progress (--score's counterfactual \
             runs) or warnings.",
        ),
        Some("Print the drawing warnings of a bundled --scenario too."),
    ),
    (
        "compare",
        Some("Print only the comparison and errors: not where --report wrote its page."),
        None,
    ),
    ("sitl build", Some("Print only the build and errors."), None),
    (
        "sim",
        Some(
            "Print only errors: not the line with the car's address (--address-file writes it) \
             or the scenario file's warnings.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "calibrate",
        Some("Print only the fit's table and errors: no progress or warnings."),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "twin check",
        Some("Print only the table and errors: no progress bar or warnings."),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "area validate",
        Some(
            "Print only the report and errors: no seed line (the report names the seed), \
             progress bar, notes or the scenario file's warnings.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "route generate",
        Some(
            "Print only the route and errors: no seed line (the route's first line names the \
             seed) or the scenario file's warnings.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "route return",
        Some(
            "Print only the route and errors: no seed line (the route's first line names the \
             seed) or the scenario file's warnings; without a route, why still prints.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "scenario import",
        Some(
            "Print only the scenario TOML and errors: not the file's drawing warnings, how its \
             coordinates were read or where the TOML was written.",
        ),
        None,
    ),
    (
        "scenario export",
        Some(
            "Print only the GeoJSON and errors: not where it was written or a scenario file's \
             drawing warnings.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    (
        "scenario check",
        Some(
            "Print only the summary line (it counts the warnings; --json lists them) and \
             errors: not the warnings.",
        ),
        Some(VERBOSE_BUNDLED),
    ),
    ("scenario list", None, None),
    ("completions", None, None),
    (
        "man",
        Some("Print only errors: not how many pages --out wrote."),
        None,
    ),
];

/// The command line's definition: [`Cli`]'s, with each command's own `-q` and `-v` help
/// ([`VERBOSITY`]). What parses the command line, `completions` and `man` use.
pub fn command() -> clap::Command {
    with_verbosity_help(<Cli as clap::CommandFactory>::command(), "")
}

/// `command`'s subcommands (under `path`, as typed) with their [`VERBOSITY`] help: their own `-q`
/// and `-v` (the same ids as [`Cli`]'s global ones, which clap then does not propagate to them,
/// and whose values it still gathers into [`Cli::quiet`] and [`Cli::verbose`]).
fn with_verbosity_help(command: clap::Command, path: &str) -> clap::Command {
    command.mut_subcommands(|sub| {
        let path = format!("{path} {}", sub.get_name()).trim_start().to_owned();
        let sub = match VERBOSITY.iter().find(|(name, _, _)| *name == path) {
            Some(&(_, quiet, verbose)) => sub
                .arg(verbosity_arg("quiet", 'q', quiet).conflicts_with("verbose"))
                .arg(verbosity_arg("verbose", 'v', verbose)),
            None => sub,
        };
        with_verbosity_help(sub, &path)
    })
}

/// `-q/--quiet` or `-v/--verbose` with `help` (without its last full stop, as clap shows a doc
/// comment's), hidden without one.
fn verbosity_arg(name: &'static str, short: char, help: Option<&'static str>) -> clap::Arg {
    clap::Arg::new(name)
        .short(short)
        .long(name)
        .action(clap::ArgAction::SetTrue)
        .help(help.map(|h| h.strip_suffix('.').unwrap_or(h)))
        .hide(help.is_none())
}

/// Parses the command line `args` (the program's name first) by [`command`].
pub fn parse_from<I, T>(args: I) -> Result<Cli, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    use clap::FromArgMatches;
    let mut command = command();
    let mut matches = command.try_get_matches_from_mut(args)?;
    let cli =
        Cli::from_arg_matches_mut(&mut matches).map_err(|error| error.format(&mut command))?;
    // Given at two levels (`drivecheck -q run -v`), clap checks each level's options apart.
    if cli.quiet && cli.verbose {
        return Err(command.error(
            clap::error::ErrorKind::ArgumentConflict,
            "-q/--quiet and -v/--verbose cannot be used together",
        ));
    }
    Ok(cli)
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a test campaign: drive generated tests with injected faults and judge UWB against
    /// RTK. Exit status: 0 every test passed, 1 a test failed or was aborted, 2 error.
    Run(RunArgs),
    /// Drive a recorded case again and compare it segment by segment: on the embedded simulated
    /// car the case's own test (the same car from the same start: every segment's largest
    /// deviation as the case's), or with --vary-seed other cars and their spread. Exit status: 0
    /// every run passed, 1 a run failed or was aborted, 2 error.
    Replay(ReplayArgs),
    /// Shrink a failing case to the smallest test that still fails the same way every time (on
    /// the embedded simulated car, in virtual time). Exit status: 0 shrunk, 1 the case does not
    /// fail the same way in every run (nothing to shrink), 2 error.
    Shrink(ShrinkArgs),
    /// Drive a case for every value of fault parameters or simulator settings (`--set`) on the
    /// embedded simulated car and tabulate each segment's largest deviation. Exit status: 0 ran,
    /// 2 error.
    Sweep(SweepArgs),
    /// List run directories (campaigns and replays) with their summary, or show one. Exit
    /// status: 0 listed or shown, 2 error.
    Runs(RunsArgs),
    /// Write a self-contained HTML report of a run, replay or shrink directory (maps, deviation
    /// plots, tables; inline SVG, no network or script needed). Exit status: 0 written, 2 error.
    Report(ReportArgs),
    /// Explain why segments failed: the ranked causes of the UWB error's growth (a fault, an
    /// anchor's ranges, the odometry, the heading), from the recorded samples. Exit status: 0
    /// explained, 2 error.
    Explain(ExplainArgs),
    /// Compare two runs of the same tests (two firmware builds, two cars): is NEW better or
    /// worse than BASE, and where? Paired and noise-aware (docs/compare.md). Exit status: 0
    /// compared (with `--fail-on regression`: and NEW is not significantly worse), 1 with
    /// `--fail-on regression` when NEW is significantly worse, 2 error (runs of other tests).
    Compare(CompareArgs),
    /// Serve a simulated car over TCP (like the reference bridge) or UDP, until Ctrl-C. Exit
    /// status: 0 stopped by Ctrl-C, 2 error.
    Sim(SimArgs),
    /// The car's own firmware built for the host (`--car sitl:TREE`, docs/sitl.md).
    #[command(subcommand)]
    Sitl(SitlCommand),
    /// Fit a car profile to recordings of a car: its cases driven again on simulated cars of
    /// candidate profiles until their UWB − RTK error matches the recorded one (docs/twin.md).
    /// Exit status: 0 fitted, 2 error.
    Calibrate(CalibrateArgs),
    /// How far the simulated car of a car profile can be trusted: drive a recorded run's cases
    /// again on it and compare (docs/twin.md).
    #[command(subcommand)]
    Twin(TwinCommand),
    /// Check a test area before any car drives in it.
    #[command(subcommand)]
    Area(AreaCommand),
    /// Generate routes in a test area.
    #[command(subcommand)]
    Route(RouteCommand),
    /// Read, check and convert scenario files.
    #[command(subcommand)]
    Scenario(ScenarioCommand),
    /// Print a shell completion script (`drivecheck completions bash > ~/.local/share/bash-completion/completions/drivecheck`).
    /// Exit status: 0 printed, 2 error.
    Completions(CompletionsArgs),
    /// Write the manual pages (roff): `drivecheck.1` and one per command, into DIR, or the main
    /// page on standard output (`drivecheck man | man -l -`). Exit status: 0 written, 2 error.
    Man(ManArgs),
}

/// Options of `drivecheck completions`.
#[derive(Debug, Args)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// Options of `drivecheck man`.
#[derive(Debug, Args)]
pub struct ManArgs {
    /// The directory to write `drivecheck.1` and `drivecheck-<command>.1` into (created if
    /// missing); without it the main page goes to standard output.
    #[arg(short = 'o', long = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Options of `drivecheck run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario: a bundled name, a .toml, a reference .xml or a .geojson file (default:
    /// `parking-lot-2anchors`, or with --cases-from the bundled scenario the earlier run names).
    #[arg(long)]
    pub scenario: Option<String>,
    /// The car: `sim` (the embedded simulated car), `tcp://HOST:PORT`, `udp://HOST:PORT` or
    /// `serial:///dev/ttyACM0`. Given again, several cars drive the campaign together, each
    /// test on whichever is free (cars behind links, each on its own track or HIL board), named
    /// `NAME=ADDRESS` (`--car a=tcp://10.0.0.5:8300`) or `car1`, `car2`, … in the order given.
    #[arg(long, default_value = "sim", value_name = "[NAME=]CAR")]
    pub car: Vec<String>,
    /// Tests in the campaign (default: the scenario's, 10 for the bundled ones; at most 1,000,000).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=scenarios::MAX_TESTS as u64))]
    pub tests: Option<usize>,
    /// The campaign's seed (printed when not given).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Plan the same tests without their fault commands.
    #[arg(long)]
    pub no_faults: bool,
    /// Drive exactly the cases of an earlier run, test for test (its case files in order, with
    /// their routes, faults and fault places), instead of generated tests: the same tests on
    /// another car, firmware or simulator seed, for `drivecheck compare`. --seed then changes
    /// only the car's noise, the resets and the safe stops (default: the earlier run's seed).
    #[arg(long, value_name = "DIR", conflicts_with = "tests")]
    pub cases_from: Option<PathBuf>,
    /// Continue the interrupted campaign of run directory DIR (Ctrl-C, a signal, a lost link, a
    /// crash or kill -9) in DIR: the same plan and settings (given ones must agree), the tests
    /// that did not end driven (one cut off is driven again from its start, its case kept as
    /// case-NNN.partial-K.json), its recording continued; --car may name another car.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["out", "cases_from", "dry_run"])]
    pub resume: Option<PathBuf>,
    /// Run the embedded simulated car against the wall clock instead of in virtual time.
    #[arg(long)]
    pub realtime: bool,
    /// The safety monitor brakes when no state sample came for this long (raised further when
    /// the measured link jitter demands it; at most 1.9 s, under the car's 2 s watchdog). The
    /// default, 500 ms, is well above the gaps of a loaded host (about 300 ms) and below the 1 s
    /// of route the streaming keeps ahead of the car (docs/method.md, Safety). Raise it on lossy
    /// links.
    #[arg(long, value_name = "DURATION", default_value = "500ms", value_parser = TypedDuration::parse)]
    pub stale_after: TypedDuration,
    /// After a segment fails the oracle: `stop` the test there (safe stop, then the next test) or
    /// `continue` driving it and record every segment (default: `stop`, or with --cases-from
    /// the earlier run's policy).
    #[arg(long, value_enum)]
    pub on_failure: Option<OnFailure>,
    /// Run in a scenario without anchors: without them the UWB estimate is dead reckoning only,
    /// so the tests say nothing about UWB positioning (campaign.json's summary says so).
    #[arg(long)]
    pub allow_no_anchors: bool,
    /// At the end, shrink every failed test's case (as `drivecheck shrink` does, on the embedded
    /// simulated car in virtual time) into `shrink-NNN/` of the run directory.
    #[arg(long)]
    pub shrink: bool,
    /// With `--shrink`: the wall-time budget of each case's shrink.
    #[arg(long, value_name = "DURATION", default_value = "2min", value_parser = humantime::parse_duration)]
    pub shrink_budget: std::time::Duration,
    /// The run directory (default `runs/<UTC timestamp>-<scenario>-<seed>/`; `runs/` is
    /// `$DRIVECHECK_RUNS_DIR` when set).
    #[arg(short, long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Also write the campaign's tests as JUnit XML to FILE (one testcase per test), for CI.
    #[arg(long, value_name = "FILE")]
    pub junit: Option<PathBuf>,
    /// At the end, also write `report.html` into the run directory (as `drivecheck report`).
    #[arg(long)]
    pub report: bool,
    /// With `--report`: draw every test's maps and plot, not only the failing and aborted
    /// tests' (as `drivecheck report --all-tests`).
    #[arg(long, requires = "report")]
    pub report_all_tests: bool,
    /// Serve every channel of the recording live over the Foxglove WebSocket protocol while the
    /// campaign runs, on loopback port 8765 unless an address is given (`0.0.0.0:8765` for the
    /// network); open it in Foxglove with *Open connection…* `ws://ADDR`. The embedded simulated
    /// car then runs against the wall clock.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    pub live: Option<std::net::SocketAddr>,
    /// Tests at once, each on a simulated car of its own (default: the number of cores for the
    /// embedded simulated car, 1 with --live; a real car runs one test at a time). Every test
    /// runs on a fresh simulated car whatever N, so the results do not depend on it.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub jobs: Option<u32>,
    /// Run only shard K of N of the campaign's tests (tests i with i mod N = K − 1), into a run
    /// directory that says so; `drivecheck runs merge` joins the shards' run directories.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<campaign::shard::Shard>,
    /// What `campaign.mcap` keeps: every test, the tests that did not pass, or no recording
    /// (case files are always written).
    #[arg(long, value_enum, value_name = "WHAT", default_value_t = RecordArg::All)]
    pub record: RecordArg,
    /// The car profile of the embedded simulated car: `default` (the bundled car) or a TOML
    /// file (`drivecheck calibrate` writes one; docs/twin.md). Only with `--car sim`.
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// Print the result as one JSON document on standard output instead of the table (the run
    /// directory, `campaign.json`'s record and every test; docs/json.md). Progress and notes stay
    /// on standard error.
    #[arg(long)]
    pub json: bool,
    /// Check the car without driving it: connect, run preflight (firmware, configuration read
    /// back, anchors, fault injection, the car inside the fence, the link's round trip), upload
    /// the first test's route with the autopilot off and its faults, read both back, clear them.
    /// Nothing is written (docs/car.md). Exit status: 0 ready, 2 not.
    #[arg(long)]
    pub dry_run: bool,
}

/// The scenario of a command about one (`area`, `route`, `scenario check`): the first positional
/// argument, or `--scenario` as every other command takes it.
#[derive(Debug, Clone, Args)]
#[group(required = true, multiple = false)]
pub struct ScenarioGiven {
    /// Scenario: a bundled name (see `drivecheck scenario list`), a .toml file, a reference .xml
    /// or a .geojson file.
    #[arg(value_name = "SCENARIO")]
    scenario_positional: Option<String>,
    /// The scenario, as every other command takes it (the same as SCENARIO).
    #[arg(long = "scenario", value_name = "SCENARIO")]
    scenario: Option<String>,
}

impl ScenarioGiven {
    /// The scenario as given (a bundled name or a file).
    pub fn name(&self) -> &str {
        // The group is required: clap gives one of the two.
        self.scenario_positional
            .as_deref()
            .or(self.scenario.as_deref())
            .unwrap_or_default()
    }
}

/// What the recording keeps (`run --record`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RecordArg {
    /// Every test.
    All,
    /// The tests that failed or were aborted.
    Failing,
    /// Nothing: no `campaign.mcap`.
    None,
}

/// What a campaign does after a failing segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnFailure {
    /// Stop the test at the failing segment (the method's default).
    Stop,
    /// Drive the rest of the test and record every segment.
    Continue,
}

/// What a command that drives one case on fresh cars is given besides the case (`replay`,
/// `shrink`, `sweep`), resolved by [`crate::settings::CaseSettings`].
#[derive(Debug, Args)]
pub struct CaseCarArgs {
    /// Scenario: a bundled name, a .toml, a reference .xml or a .geojson file (default: the
    /// bundled scenario the case names, else the copy the recording beside the case holds).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Drive the case even when the scenario's hash differs from the case's (or the case has
    /// none).
    #[arg(long)]
    pub ignore_scenario_hash: bool,
    /// The campaign seed: of the reset's return route, the safe stop and the simulated car, and
    /// of the first run of every candidate (`shrink`) or value (`sweep`), run k with seed + k − 1
    /// (default: the case's campaign seed, which drives the case's own test again: the same
    /// simulated car from the same start).
    #[arg(long)]
    pub seed: Option<u64>,
    /// The car profile of the simulated car the case is driven on: `default` or a TOML file
    /// (docs/twin.md). Not with a car behind a link; `replay` warns when the case was driven on
    /// another profile.
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// The car: `sim` (a fresh embedded simulated car for every run), `sitl:TREE` (the car's own
    /// firmware tree, built for the host, driving the same physical car in virtual time;
    /// docs/sitl.md), and for `replay` also a car behind a link: `tcp://HOST:PORT`,
    /// `udp://HOST:PORT` or `serial:///dev/ttyACM0`.
    #[arg(long, value_name = "CAR", default_value = "sim")]
    pub car: String,
}

/// Options of `drivecheck replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The case file to drive again (a `case-NNN.json` of a run directory, or written by hand:
    /// see docs/case-format.md).
    #[arg(value_name = "CASE.json")]
    pub case: PathBuf,
    /// How many times to drive it (default: once, or 3 times with --vary-seed, --realtime or a
    /// real car). On the embedded simulated car in virtual time the case's own test gives the
    /// same figures every time, so more than one run there implies --vary-seed (the summary
    /// says so).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub times: Option<u32>,
    /// Leave out the case's fault commands (does the failure disappear without them?).
    #[arg(long)]
    pub no_faults: bool,
    /// Drive the case's test on other simulated cars (other sensor noise each run, seeded by
    /// the seed map) and report the spread, instead of the case's own car.
    #[arg(long)]
    pub vary_seed: bool,
    /// Run the embedded simulated car against the wall clock instead of in virtual time.
    #[arg(long)]
    pub realtime: bool,
    /// The replay directory (default `runs/<UTC timestamp>-replay-<scenario>-<seed>/`, in
    /// `$DRIVECHECK_RUNS_DIR` when set); each run
    /// writes a run directory `run-1/`, `run-2/`, … inside it, the comparison `replay.json`.
    #[arg(short, long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Also write the runs as JUnit XML to FILE (one testcase per run), for CI.
    #[arg(long, value_name = "FILE")]
    pub junit: Option<PathBuf>,
    /// At the end, also write `report.html` into the replay directory (as `drivecheck report`).
    #[arg(long)]
    pub report: bool,
    /// Print the comparison as one JSON document on standard output instead of the table
    /// (docs/json.md).
    #[arg(long)]
    pub json: bool,
    /// The scenario, the seed and the car the case is driven on.
    #[command(flatten)]
    pub drive: CaseCarArgs,
}

/// Options of `drivecheck shrink`.
#[derive(Debug, Args)]
pub struct ShrinkArgs {
    /// The failing case file (a `case-NNN.json` of a run directory, a replay's, or written by
    /// hand).
    #[arg(value_name = "CASE.json")]
    pub case: PathBuf,
    /// The shrink directory (default `runs/<UTC timestamp>-shrink-<scenario>-<seed>/`, in
    /// `$DRIVECHECK_RUNS_DIR` when set): it gets
    /// `minimal.json` and `shrink.json`.
    #[arg(short, long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Runs of every candidate (run k with seed + k − 1): it is kept only when all of them fail
    /// the same way.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=50))]
    pub runs: u32,
    /// Keep a candidate only when every run's largest deviation in the failing segment is this
    /// far above the threshold, metres (at most the case's own least clear failure): the method
    /// saw reruns agree within about 0.1 m, so a case failing by less may pass on the car.
    #[arg(long, value_name = "METRES", default_value_t = 0.1)]
    pub margin: f64,
    /// Stop after this much wall time with the smallest case found so far.
    #[arg(long, value_name = "DURATION", default_value = "2min", value_parser = humantime::parse_duration)]
    pub budget: std::time::Duration,
    /// Print the result as one JSON document on standard output instead of the table (the
    /// shrink report, or why the case was not shrunk; docs/json.md).
    #[arg(long)]
    pub json: bool,
    /// The scenario, the seed and the car the case is driven on.
    #[command(flatten)]
    pub drive: CaseCarArgs,
}

/// Options of `drivecheck sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// The case file to sweep.
    #[arg(value_name = "CASE.json")]
    pub case: PathBuf,
    /// `NAME=V1,V2,…`: a parameter and its values; several `--set`s sweep every combination.
    /// NAME is `fault[i].param`, `fault[i].start` or `fault[i].duration` (the case's i-th fault
    /// command, from 0), or a setting of the simulated car: `sim.uwb_clamp_m` (the UWB
    /// estimator's largest correction per range, 0.2 m in the firmware), `sim.anchor_error_m`
    /// (how far each anchor stands from its surveyed position), `sim.range_sigma_m` (the noise
    /// of one UWB exchange).
    #[arg(long, value_name = "NAME=V1,V2,…", required = true)]
    pub set: Vec<String>,
    /// Runs of every value (run k with seed + k − 1).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=50))]
    pub runs: u32,
    /// Print the result as JSON (`drivecheck-sweep`, docs/case-format.md) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// The scenario, the seed and the car the case is driven on.
    #[command(flatten)]
    pub drive: CaseCarArgs,
}

/// Options of `drivecheck report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The run directory (`campaign.json`), replay directory (`replay.json`) or shrink directory
    /// (`shrink.json`).
    #[arg(value_name = "RUN_DIR")]
    pub dir: PathBuf,
    /// Where to write the page (default `RUN_DIR/report.html`).
    #[arg(short, long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Scenario to draw the maps in: a bundled name, a .toml file or a reference .xml (default:
    /// the scenario stored in the recording, else the bundled one the run names).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Draw every test's maps and plot; by default a campaign's passing tests are rows of the
    /// tests table only, so the page does not grow with them.
    #[arg(long)]
    pub all_tests: bool,
}

/// Options of `drivecheck compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The run directory compared against (`campaign.json` and its case files).
    #[arg(value_name = "BASE")]
    pub base: PathBuf,
    /// The run directory judged: the same tests (same scenario, seed and tool), driven on the
    /// other build or car.
    #[arg(value_name = "NEW")]
    pub new: PathBuf,
    /// Print the comparison as one JSON document (docs/json.md) instead of the summary.
    #[arg(long)]
    pub json: bool,
    /// Also write the comparison as an HTML page: FILE, or `compare.html` in NEW's run
    /// directory (`--report=FILE`).
    #[arg(long, value_name = "FILE", num_args = 0..=1, require_equals = true)]
    pub report: Option<Option<PathBuf>>,
    /// Exit with status 1 when NEW is significantly worse than BASE (for CI).
    #[arg(long, value_name = "WHAT")]
    pub fail_on: Option<FailOn>,
    /// The significance level: the chance of calling a difference that is only noise, at most.
    #[arg(long, default_value_t = campaign::compare::DEFAULT_ALPHA, value_name = "ALPHA")]
    pub alpha: f64,
    /// The noise of a segment's largest deviation, metres: a change larger than this is worse
    /// (or better) than the noise (default 0.2 m, docs/compare.md).
    #[arg(long, value_name = "M", conflicts_with = "noise_from")]
    pub noise: Option<f64>,
    /// Measure the noise instead: DIR is BASE's tests driven again on the same car with another
    /// seed; the noise is the 95th percentile of the segments' |change| between BASE and DIR.
    #[arg(long, value_name = "DIR")]
    pub noise_from: Option<PathBuf>,
    /// The seed of the bootstrap's resamples and of the sign-flip test's assignments (the same
    /// seed gives the same interval and p).
    #[arg(long, default_value_t = campaign::compare::DEFAULT_BOOTSTRAP_SEED)]
    pub seed: u64,
}

/// What `drivecheck compare --fail-on` fails on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FailOn {
    /// NEW significantly worse than BASE (by McNemar's test on the tests' verdicts or by the
    /// median change of the segments' largest deviation).
    Regression,
}

/// Options of `drivecheck explain`.
#[derive(Debug, Args)]
pub struct ExplainArgs {
    /// A case file of a run directory (`case-NNN.json`), the run directory (every test), or a
    /// replay directory (every run).
    #[arg(value_name = "CASE.json|RUN_DIR")]
    pub target: PathBuf,
    /// Print the explanations as JSON (`{"cases": [{"case": …, "segments": [...]}]}`).
    #[arg(long)]
    pub json: bool,
    /// Explain every judged segment, not only the failing ones.
    #[arg(long)]
    pub all_segments: bool,
    /// Also score the explanations against the simulated car's hidden truth (which fault
    /// applied, which range was reflected) and print the confusion matrix: for a run directory
    /// recorded against the embedded simulated car.
    #[arg(long)]
    pub score: bool,
    /// With `--score`: where two or more faults moved the estimate in a failing segment, drive
    /// its case again this many times (seeds from the campaign's) as it was and without each of
    /// them, on the embedded simulated car in virtual time; the truth is the fault whose absence
    /// lowers the segment's largest deviation most. 0: rank them by how far each pushed its probe.
    #[arg(long, default_value_t = 3, value_name = "RUNS")]
    pub counterfactual_runs: u32,
    /// Scenario of the run (default: the one stored in the recording, else the bundled one the
    /// run names).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Calibrate instead: print the nominal level and the least growth that a fault-free run
    /// (`drivecheck run --no-faults`) gives at the false-alarm budget, for `--nominal` and
    /// `--min-growth`.
    #[arg(long)]
    pub calibrate: bool,
    /// The false-alarm budget of `--calibrate`: the share of fault-free samples above the
    /// nominal level, and of fault-free segments with a cause.
    #[arg(long, default_value_t = 0.01)]
    pub budget: f64,
    /// The error level taken as nominal, metres: the growth explained starts where the error
    /// last was at or below it.
    #[arg(long, value_name = "M")]
    pub nominal: Option<f64>,
    /// A cause that explains less growth than this, metres, is left to `unexplained`.
    #[arg(long, value_name = "M")]
    pub min_growth: Option<f64>,
    /// With `--score`: the car profile of the simulated cars the counterfactual drives: `default`
    /// or a TOML file (docs/twin.md).
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// With `--score`: the simulated car the counterfactual drives: `sim` (the embedded simulated car) or
    /// `sitl:TREE` (the car's own firmware tree, built for the host, driving the same physical
    /// car in virtual time; docs/sitl.md).
    #[arg(long, value_name = "sim|sitl:TREE", default_value = "sim")]
    pub car: String,
}

/// Options of `drivecheck runs`.
#[derive(Debug, Args)]
pub struct RunsArgs {
    /// Where the run directories are (where `run`, `replay` and `shrink` put them by default).
    #[arg(
        long,
        env = "DRIVECHECK_RUNS_DIR",
        default_value = "runs",
        value_name = "DIR"
    )]
    pub dir: PathBuf,
    /// Print the list, the run directory shown or the merge's result as one JSON document on
    /// standard output (docs/json.md).
    #[arg(long, global = true)]
    pub json: bool,
    /// Show one run directory instead of listing them.
    #[command(subcommand)]
    pub command: Option<RunsCommand>,
}

/// Subcommands of `drivecheck runs`.
#[derive(Debug, Subcommand)]
pub enum RunsCommand {
    /// Show a run directory: its campaign record and every test, or a replay's comparison. Exit
    /// status: 0 shown (whatever its tests' verdicts), 2 error.
    Show {
        /// The run directory (a path, or a name inside `--dir`).
        #[arg(value_name = "DIR")]
        run: PathBuf,
        /// Also what the campaign covered: the share of the area driven, the headings and speeds
        /// driven, the fault types per probe planned, confirmed and acting, segments per test.
        #[arg(long)]
        coverage: bool,
    },
    /// Join the run directories of a campaign's shards (`run --shard K/N`) into the run
    /// directory of the whole campaign: every case file, `campaign.json` with the summary over all
    /// tests, one `campaign.mcap` in test order. Refuses shards of different campaigns and names
    /// the shards missing. Exit status: 0 merged (whatever its tests' verdicts), 2 error.
    Merge {
        /// The shards' run directories.
        #[arg(value_name = "DIR", required = true, num_args = 1..)]
        shards: Vec<PathBuf>,
        /// The run directory to write (must not exist or be empty).
        #[arg(short, long, value_name = "DIR")]
        out: PathBuf,
        /// The scenario the shards ran, when it is not bundled (a .toml or reference .xml file).
        #[arg(long)]
        scenario: Option<String>,
        /// Also write the whole campaign's tests as JUnit XML to FILE (one testcase per test).
        #[arg(long, value_name = "FILE")]
        junit: Option<PathBuf>,
    },
}

/// Options of `drivecheck sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// Scenario: a bundled name, a .toml, a reference .xml or a .geojson file.
    #[arg(long)]
    pub scenario: String,
    /// Address to listen on (loopback unless told otherwise); port 0 takes any free port, so
    /// that several simulated cars on one machine never collide.
    #[arg(long, default_value = "127.0.0.1:8300")]
    pub listen: std::net::SocketAddr,
    /// Write the car's address (`tcp://127.0.0.1:41234`, for `run --car`) to FILE once it
    /// listens: with `--listen 127.0.0.1:0`, how a script learns the port.
    #[arg(long, value_name = "FILE")]
    pub address_file: Option<PathBuf>,
    /// Which car to serve: `sim`, the embedded simulated car, or `sitl:TREE`, the car's own
    /// firmware built from TREE for the host and run in real time in the simulated car's world (a
    /// HIL board without the board; TCP only, no link impairment; docs/sitl.md).
    #[arg(long, default_value = "sim", value_name = "sim|sitl:TREE")]
    pub car: String,
    /// Serve UDP instead of TCP (replies go to the sender's address at the port + 1).
    #[arg(long)]
    pub udp: bool,
    /// Firmware generation: 10.1 or 12.3 (default: the profile's, 10.1 for the default car).
    #[arg(long)]
    pub firmware: Option<String>,
    /// Seed of the simulation's random draws (physics and link).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Added one-way latency of the link, for example `150ms`.
    #[arg(long, value_parser = humantime::parse_duration)]
    pub link_latency: Option<std::time::Duration>,
    /// Extra one-way delay drawn uniformly from 0 to this, for example `40ms`.
    #[arg(long, value_parser = humantime::parse_duration)]
    pub link_jitter: Option<std::time::Duration>,
    /// Probability that a payload is lost, for example `2%` or `0.02`.
    #[arg(long, value_parser = parse_probability)]
    pub link_loss: Option<f64>,
    /// Over TCP, disconnect a client that sent no complete frame for this long, so a silent
    /// client, or one trickling bytes that make no frame, does not hold the car's only connection
    /// (`0s`: never).
    #[arg(long, value_name = "DURATION", default_value = "30s", value_parser = humantime::parse_duration)]
    pub idle_timeout: std::time::Duration,
    /// The car profile: `default` or a TOML file (docs/twin.md); `--firmware` overrides its
    /// firmware.
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
}

/// Parses `2%` or `0.02` into a probability in 0..=1.
pub fn parse_probability(text: &str) -> Result<f64, String> {
    let (number, scale) = match text.trim().strip_suffix('%') {
        Some(percent) => (percent, 100.0),
        None => (text.trim(), 1.0),
    };
    let value = number
        .trim()
        .parse::<f64>()
        .map_err(|e| format!("{text:?}: {e}"))?
        / scale;
    if !(0.0..=1.0).contains(&value) {
        return Err(format!(
            "{text:?}: a probability is between 0 and 1 (0–100 %)"
        ));
    }
    Ok(value)
}

/// Options of `drivecheck calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Run directories of campaigns on the car (their case files and `campaign.mcap`, recorded
    /// with `--record all`), in one scenario.
    #[arg(required = true, value_name = "RUN_DIR")]
    pub runs: Vec<PathBuf>,
    /// Where to write the fitted profile (TOML).
    #[arg(short, long, value_name = "FILE")]
    pub out: PathBuf,
    /// The wall-time budget of the fit; the best profile so far is written when it is spent.
    #[arg(long, value_name = "DURATION", default_value = "10min", value_parser = humantime::parse_duration)]
    pub budget: std::time::Duration,
    /// No new batch of candidate profiles after this many (a bound that, unlike `--budget`, gives
    /// the same fit on any machine; a batch is one candidate per parameter, or two).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..))]
    pub max_evaluations: Option<u32>,
    /// Simulated runs of every case per candidate profile (more: a smoother misfit, slower).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub sim_runs: u32,
    /// The profile to start from (and to keep what is not fitted from): `default` or a file.
    #[arg(long, value_name = "FILE")]
    pub from: Option<PathBuf>,
    /// Descents from other starting points after the first, while the budget lasts (each about
    /// as long as the first): a parameter another descent puts elsewhere with as good a fit is
    /// named not identified, and the best fit is kept.
    #[arg(long, value_name = "N", default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=16))]
    pub restarts: u32,
    /// Candidate profiles driven at once, each on a thread of its own (default: the number of
    /// cores). The fit does not depend on it.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub jobs: Option<u32>,
    /// The scenario file, when the runs' is not bundled.
    #[arg(long)]
    pub scenario: Option<String>,
    /// Use the runs although the scenario's hash is not the one they were recorded in.
    #[arg(long)]
    pub ignore_scenario_hash: bool,
    /// The simulated car the candidate profiles are driven on: `sim` (the embedded simulated car)
    /// or `sitl:TREE` (the car's own firmware tree, built for the host, in each candidate's
    /// physical car: the fit is then of the car around the firmware it runs; docs/sitl.md).
    #[arg(long, value_name = "sim|sitl:TREE", default_value = "sim")]
    pub car: String,
}

/// `drivecheck sitl …`
#[derive(Debug, Subcommand)]
pub enum SitlCommand {
    /// Build a firmware tree for the host (or take it from the cache, by a hash of the tree's
    /// sources, the shim and the compiler): print its firmware version, the tree's hash, the
    /// executable, the files compiled and the symbols the shim provides. Exit status: 0 built,
    /// 2 error (naming the file, the missing symbol or the compiler's first error).
    Build(SitlBuildArgs),
}

/// Options of `drivecheck sitl build`.
#[derive(Debug, Args)]
pub struct SitlBuildArgs {
    /// The firmware tree: the folder with the firmware's `main.c` and `conf_general.h`
    /// (`rise_sdvp/Embedded/RC_Controller`).
    #[arg(value_name = "TREE")]
    pub tree: PathBuf,
    /// Print the build as one JSON document (docs/json.md).
    #[arg(long)]
    pub json: bool,
}

/// `drivecheck twin …`
#[derive(Debug, Subcommand)]
pub enum TwinCommand {
    /// Drive every recorded case of a run again on simulated cars of a profile (and of the
    /// default car, for comparison), N runs each with other seeds, and compare per segment with
    /// the recording: the share of verdicts agreed, the median and p90 of |recorded − simulated
    /// median| largest deviation. Writes `twin.json` into the run directory. Exit status: 0
    /// checked, 2 error.
    Check(TwinCheckArgs),
}

/// Options of `drivecheck twin check`.
#[derive(Debug, Args)]
pub struct TwinCheckArgs {
    /// The run directory of a campaign on the car (its case files and `campaign.json`).
    pub run: PathBuf,
    /// The car profile to check: a TOML file (`default`: the bundled car alone).
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// Simulated runs per case.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub runs: u32,
    /// The same cases driven again on the car (`drivecheck run` with the same `--seed` and
    /// `--tests` on the same car): the car's own repeatability, the best a twin can reach.
    #[arg(long, value_name = "RUN_DIR")]
    pub repeat: Option<PathBuf>,
    /// Print `twin.json` instead of the table.
    #[arg(long)]
    pub json: bool,
    /// The scenario file, when the run's is not bundled.
    #[arg(long)]
    pub scenario: Option<String>,
    /// Drive the cases although the scenario's hash is not the one they were recorded in.
    #[arg(long)]
    pub ignore_scenario_hash: bool,
    /// The simulated car the cases are driven on: `sim` (the embedded simulated car) or
    /// `sitl:TREE` (the car's own firmware tree, built for the host, driving the profile's
    /// physical car in virtual time: a twin of the car with its own firmware; docs/sitl.md).
    #[arg(long, value_name = "sim|sitl:TREE", default_value = "sim")]
    pub car: String,
}

/// `drivecheck area …`
#[derive(Debug, Subcommand)]
pub enum AreaCommand {
    /// Drive one long generated trajectory through the area and give a verdict (see
    /// docs/method.md#validating-an-area).
    ///
    /// The area is `safe` when no extension failed and no extension needed more than half the
    /// generator's outer tries. Exit status: 0 safe, 1 unsafe, 2 error.
    Validate(ValidateArgs),
}

/// Options of `drivecheck area validate`.
#[derive(Debug, Args)]
pub struct ValidateArgs {
    /// The scenario (`SCENARIO` or `--scenario`).
    #[command(flatten)]
    pub scenario: ScenarioGiven,
    /// Length of the trajectory, kilometres.
    #[arg(long, default_value_t = 100.0)]
    pub km: f64,
    /// Seed of the random trajectory (printed when not given).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Write a picture (area, trajectory sample, coverage heat map, hot spots) to this SVG file
    /// (`--svg` is an older name of this option).
    #[arg(short = 'o', long = "out", alias = "svg", value_name = "FILE.svg")]
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
    /// size (4–7 points by default), each proven drivable by the ahead margin. Exit status: 0 a
    /// route, 2 error (an extension the generator could not find, a bad argument).
    Generate(GenerateArgs),
    /// Plan the return route from a pose to the scenario's recovery route (what the car drives
    /// between tests), with its length, a lower bound and their ratio. Exit status: 0 a route,
    /// 1 no route found, 2 error (a pose outside the area, a bad argument).
    Return(ReturnArgs),
}

/// Options of `drivecheck route return`.
#[derive(Debug, Args)]
pub struct ReturnArgs {
    /// The scenario (`SCENARIO` or `--scenario`).
    #[command(flatten)]
    pub scenario: ScenarioGiven,
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
    pub planner: recovery::PlannerKind,
    /// Print the route as JSON on standard output.
    #[arg(long)]
    pub json: bool,
}

/// Options of `drivecheck route generate`.
#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// The scenario (`SCENARIO` or `--scenario`).
    #[command(flatten)]
    pub scenario: ScenarioGiven,
    /// How many points to generate after the start route. They come in extensions of the
    /// scenario's segment size (4–7 by default), every one within it whenever the number allows
    /// (with 4–7, any number of at least 4); fewer than 4 are one short extension.
    #[arg(long)]
    pub points: usize,
    /// Seed of the random route (printed when not given).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Speed of the generated points, km/h (as the scenario's campaign speeds), at most the
    /// autopilot's top speed of 30 km/h (default: the scenario's lowest campaign speed). The
    /// route's points carry it in m/s, as scenario files do.
    #[arg(long, value_name = "KM/H")]
    pub speed_kmh: Option<f64>,
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
    /// Convert a reference route XML file or a GeoJSON FeatureCollection (QGIS, geojson.io,
    /// `scenario export --geojson`; docs/geojson.md) into a scenario TOML file. Exit status: 0
    /// converted, 2 error (a file that cannot be read or is invalid, coordinates whose kind is
    /// ambiguous without --crs).
    Import(ImportArgs),
    /// Write a scenario as a GeoJSON FeatureCollection for QGIS or geojson.io (docs/geojson.md):
    /// RFC 7946, WGS84 longitude/latitude with rings by the right-hand rule, which needs an
    /// origin (the scenario's own or --origin); local metres only with --crs local. Exit status:
    /// 0 written, 2 error (an unknown scenario, no origin for longitude/latitude, a file that
    /// cannot be written).
    Export(ExportArgs),
    /// Load and validate a scenario and plan its first test as run does; print its warnings (a
    /// bundled scenario's with -v: they are about data you cannot change). Exit status: 0 valid,
    /// 2 invalid (run would refuse it).
    Check(CheckArgs),
    /// List the bundled scenarios. Exit status: 0 listed, 2 error.
    List(ListArgs),
}

/// Options of `drivecheck scenario import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The file: reference XML (`.xml`), or GeoJSON (`.geojson`, `.json`, or text that starts
    /// with `{`).
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// A reference XML file that holds only the anchors (`<routes><anchors>…</anchors></routes>`),
    /// merged into the imported XML area (which must then have none of its own).
    #[arg(long, value_name = "ANCHORS.xml")]
    pub anchors: Option<PathBuf>,
    /// GeoJSON only: the coordinates are WGS84 longitude/latitude or local metres, when the file
    /// does not say (default: inferred from the numbers, refused when both are plausible).
    #[arg(long, value_enum)]
    pub crs: Option<CrsArg>,
    /// GeoJSON only: the local frame's origin, latitude and longitude in degrees and the
    /// ellipsoidal height in metres (default 0); longitude/latitude are converted to metres
    /// around it (default: the file's origin, else the fence's first vertex).
    #[arg(long, value_name = "LAT,LON[,H]", value_parser = parse_origin, allow_hyphen_values = true)]
    pub origin: Option<scenarios::EnuOrigin>,
    /// Where to write the scenario TOML (standard output when not given).
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace the `--out` file if it exists.
    #[arg(long)]
    pub force: bool,
}

/// Options of `drivecheck scenario export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The scenario (`SCENARIO` or `--scenario`).
    #[command(flatten)]
    pub scenario: ScenarioGiven,
    /// Write GeoJSON (RFC 7946), the only export format: the option may be left out.
    #[arg(long)]
    pub geojson: bool,
    /// The coordinates: `wgs84` longitude/latitude (the default; it needs an origin, the
    /// scenario's or --origin) or `local` metres (reads back to the same scenario hash; not
    /// RFC 7946, and said so in the file).
    #[arg(long, value_enum)]
    pub crs: Option<CrsArg>,
    /// The local frame's origin on the globe, in place of the scenario's: latitude and longitude
    /// in degrees, the ellipsoidal height in metres (default 0).
    #[arg(long, value_name = "LAT,LON[,H]", value_parser = parse_origin, allow_hyphen_values = true)]
    pub origin: Option<scenarios::EnuOrigin>,
    /// Where to write the GeoJSON (standard output when not given).
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace the `--out` file if it exists.
    #[arg(long)]
    pub force: bool,
}

/// The kind of coordinates of a GeoJSON file, as named on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CrsArg {
    /// WGS84 longitude and latitude, degrees (RFC 7946; QGIS, geojson.io).
    Wgs84,
    /// Local metres, x east and y north of the origin (drivecheck's own).
    Local,
}

impl From<CrsArg> for scenarios::geojson::Crs {
    fn from(arg: CrsArg) -> Self {
        match arg {
            CrsArg::Wgs84 => scenarios::geojson::Crs::Wgs84,
            CrsArg::Local => scenarios::geojson::Crs::Local,
        }
    }
}

/// Parses `LAT,LON` or `LAT,LON,H` (degrees, degrees, metres) into an ENU origin.
pub fn parse_origin(text: &str) -> Result<scenarios::EnuOrigin, String> {
    let numbers = text
        .split(',')
        .map(|n| n.trim().parse::<f64>().map_err(|e| format!("{n:?}: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    let (lat, lon, height) = match numbers[..] {
        [lat, lon] => (lat, lon, 0.0),
        [lat, lon, height] => (lat, lon, height),
        _ => return Err(format!("{text:?}: expected LAT,LON or LAT,LON,H")),
    };
    if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) || !height.is_finite() {
        return Err(format!(
            "{text:?}: latitude within ±90°, longitude within ±180°, a finite height"
        ));
    }
    Ok(scenarios::EnuOrigin { lat, lon, height })
}

/// Options of `drivecheck scenario check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The scenario (`SCENARIO` or `--scenario`).
    #[command(flatten)]
    pub scenario: ScenarioGiven,
    /// Print the summary and the warnings as one JSON document on standard output.
    #[arg(long)]
    pub json: bool,
}

/// Options of `drivecheck scenario list`.
#[derive(Debug, Args)]
pub struct ListArgs {
    /// Print the list as one JSON document (an array) on standard output.
    #[arg(long)]
    pub json: bool,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_probability_is_a_fraction_or_a_percentage() {
        assert_eq!(parse_probability("2%"), Ok(0.02));
        assert_eq!(parse_probability("0.02"), Ok(0.02));
        assert_eq!(parse_probability(" 100 % "), Ok(1.0));
        assert!(parse_probability("101%").is_err());
        assert!(parse_probability("-0.1").is_err());
        assert!(parse_probability("lots").is_err());
    }

    #[test]
    fn run_defaults_to_the_embedded_car_on_the_two_anchor_lot() {
        let cli = parse_from(["drivecheck", "run"]).unwrap();
        let Command::Run(args) = cli.command else {
            panic!("not the run command");
        };
        assert_eq!(args.car, ["sim"]);
        // Resolved by the command: the two-anchor lot, or the scenario of --cases-from's run.
        assert_eq!(args.scenario, None);
        assert!(args.cases_from.is_none() && args.on_failure.is_none());
        assert!(!args.realtime && !args.no_faults);
    }

    /// The commands that do something (as typed), from the built definition: every command but
    /// clap's `help` and the groups that only hold subcommands.
    fn commands() -> Vec<(String, clap::Command)> {
        fn walk(command: &clap::Command, path: &str, found: &mut Vec<(String, clap::Command)>) {
            for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
                let path = format!("{path} {}", sub.get_name()).trim_start().to_owned();
                if !sub.is_subcommand_required_set() {
                    found.push((path.clone(), sub.clone()));
                }
                walk(sub, &path, found);
            }
        }
        let mut root = command();
        root.build();
        let mut found = Vec::new();
        walk(&root, "", &mut found);
        found
    }

    #[test]
    fn every_command_says_what_quiet_and_verbose_do_for_it() {
        let commands = commands();
        let names: Vec<&str> = commands.iter().map(|(n, _)| n.as_str()).collect();
        for (name, _, _) in VERBOSITY {
            assert!(names.contains(name), "VERBOSITY names no command {name}");
        }
        let generic = |id: &str| {
            let mut root = command();
            root.build();
            root.get_arguments()
                .find(|a| a.get_id() == id)
                .and_then(|a| a.get_help().map(ToString::to_string))
                .unwrap()
        };
        for (name, command) in &commands {
            let entry = VERBOSITY.iter().find(|(n, _, _)| n == name);
            let (_, quiet, verbose) = entry.unwrap_or_else(|| panic!("{name}: not in VERBOSITY"));
            for (id, help) in [("quiet", quiet), ("verbose", verbose)] {
                let arg = command
                    .get_arguments()
                    .find(|a| a.get_id() == id)
                    .unwrap_or_else(|| panic!("{name}: no --{id}"));
                assert_eq!(arg.is_hide_set(), help.is_none(), "{name} --{id}");
                let said = arg.get_help().map(ToString::to_string);
                let help = help.map(|h| h.strip_suffix('.').unwrap_or(h));
                assert_eq!(said.as_deref(), help, "{name} --{id}");
                assert_ne!(said, Some(generic(id)), "{name} --{id}: its own help");
            }
        }
    }

    #[test]
    fn quiet_and_verbose_are_taken_before_and_after_the_command() {
        for args in [
            &["drivecheck", "-q", "run"][..],
            &["drivecheck", "run", "-q"],
            &["drivecheck", "scenario", "check", "courtyard", "--quiet"],
            &["drivecheck", "-q", "scenario", "list"],
            &["drivecheck", "completions", "bash", "-q"],
        ] {
            let cli = parse_from(args).unwrap();
            assert!(cli.quiet && !cli.verbose, "{args:?}");
        }
        let cli = parse_from(["drivecheck", "runs", "show", "x", "-v"]).unwrap();
        assert!(cli.verbose && !cli.quiet);
        for args in [
            &["drivecheck", "run", "-q", "-v"][..],
            &["drivecheck", "-q", "-v", "run"],
            &["drivecheck", "area", "validate", "courtyard", "-v", "-q"],
            &["drivecheck", "-q", "run", "-v"],
            &["drivecheck", "-v", "scenario", "list", "-q"],
        ] {
            assert!(parse_from(args).is_err(), "{args:?}: -q and -v together");
        }
    }

    #[test]
    fn sim_takes_human_durations() {
        let cli = parse_from([
            "drivecheck",
            "sim",
            "--scenario",
            "courtyard",
            "--link-latency",
            "150ms",
            "--link-loss",
            "2%",
        ])
        .unwrap();
        let Command::Sim(args) = cli.command else {
            panic!("not the sim command");
        };
        assert_eq!(
            args.link_latency,
            Some(std::time::Duration::from_millis(150))
        );
        assert_eq!(args.link_loss, Some(0.02));
        assert!(args.listen.ip().is_loopback());
    }
}

/// A duration as the user typed it: its value and its text, so that an error about it says a
/// limit in the unit typed (`--stale-after 5s`: "at most 1.9 s").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TypedDuration {
    /// The duration.
    pub value: std::time::Duration,
    /// As typed.
    pub text: String,
}

impl TypedDuration {
    /// Reads a duration as `humantime` does (`500ms`, `1.5s` is not one: `1s 500ms`).
    pub fn parse(text: &str) -> Result<Self, humantime::DurationError> {
        Ok(Self {
            value: humantime::parse_duration(text)?,
            text: text.to_owned(),
        })
    }

    /// `duration` in the unit of the last number typed: `1.9 s` for `5s`, `1900 ms` for
    /// `3000ms`, `0.031667 min` for `1min` (seconds when the text names no unit).
    pub fn in_typed_units(&self, duration: std::time::Duration) -> String {
        let unit: String = {
            let reversed: String = self
                .text
                .trim()
                .chars()
                .rev()
                .take_while(|c| c.is_alphabetic())
                .collect();
            reversed.chars().rev().collect()
        };
        let (seconds, name) = match unit.as_str() {
            "nsec" | "ns" => (1e-9, "ns"),
            "usec" | "us" | "µs" => (1e-6, "µs"),
            "msec" | "ms" => (1e-3, "ms"),
            "min" | "mins" | "minute" | "minutes" | "m" => (60.0, "min"),
            "hr" | "hrs" | "hour" | "hours" | "h" => (3600.0, "h"),
            _ => (1.0, "s"),
        };
        let value = format!("{:.6}", duration.as_secs_f64() / seconds);
        let value = value.trim_end_matches('0').trim_end_matches('.');
        format!("{value} {name}")
    }
}

#[cfg(test)]
mod typed_duration_tests {
    use super::TypedDuration;
    use std::time::Duration;

    #[test]
    fn a_limit_is_said_in_the_unit_typed() {
        let limit = Duration::from_millis(1900);
        let said = |text: &str| TypedDuration::parse(text).unwrap().in_typed_units(limit);
        assert_eq!(said("5s"), "1.9 s");
        assert_eq!(said("3000ms"), "1900 ms");
        assert_eq!(said("1min"), "0.031667 min");
        assert_eq!(said("2s 500ms"), "1900 ms");
        assert_eq!(said("4 seconds"), "1.9 s");
    }
}
