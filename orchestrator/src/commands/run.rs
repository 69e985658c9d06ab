//! `drivecheck run`: a test campaign against the embedded simulated car (in virtual time by
//! default, or against the wall clock) or a car behind TCP, UDP or a serial port.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use car_link::CarAddress;
use car_link::firmware::{MAX_STALE_LIMIT, WATCHDOG};
use scenarios::Scenario;

use super::cases_from::CasesRun;
use super::progress::Progress;
use super::resume::Resumed;
use super::shrink;
use super::signals::{Interrupt, runtime, sim_view};
use super::table::{CampaignFailed, print_report};
use crate::cli::{RecordArg, RunArgs};
use crate::exit::Exit;
use crate::output;
use crate::scenario_arg::{load_scenario, print_warnings};
use crate::seed::choose_seed;
use crate::settings::{Origin, OutDir, Recorded, RunSettings, ScenarioFrom};
use campaign::files::Case;
use campaign::model::Campaign;
use campaign::oracle::FailurePolicy;
use campaign::oracle::Verdict;
use campaign::shrink::MINIMAL_FILE;
use recording::live::LiveView;
use report::REPORT_FILE;
use report::explain::{ExplainOptions, describe, explain_run};
use runner::junit;
use runner::vehicle::{EmbeddedSims, connect};
use runner::{
    CampaignReport, CasesSource, RecordMode, RunConfig, Tests, run_campaign, run_campaign_fresh,
    run_dir_name,
};

/// The scenario of a campaign when none is given.
const DEFAULT_SCENARIO: &str = "parking-lot-2anchors";

/// Runs the campaign and prints the final table. Exit status: 0 every test passed, 1 a test
/// failed or was aborted, 2 an error (preflight refused, link lost, interrupted, …).
pub fn run(args: &RunArgs) -> Result<Exit> {
    let resumed = args.resume.as_deref().map(Resumed::read).transpose()?;
    // A resumed campaign that drove an earlier run's cases drives them again.
    let cases_dir = match &resumed {
        Some(resumed) => resumed
            .record
            .cases_from
            .as_ref()
            .map(|c| std::path::PathBuf::from(&c.run)),
        None => args.cases_from.clone(),
    };
    let source = cases_dir.as_deref().map(CasesRun::read).transpose()?;
    let origin = match (&resumed, &source) {
        (Some(resumed), _) => Origin::Resumed {
            recorded: Recorded::from(&resumed.record),
            dir: resumed.dir.clone(),
        },
        (None, Some(source)) => Origin::CasesFrom {
            recorded: Recorded::from(&source.record),
            cases: source.files.len(),
        },
        (None, None) => Origin::Fresh,
    };
    let settings = RunSettings::resolve(args, &origin);
    let scenario_arg = match (&settings.scenario, &resumed, &source) {
        (ScenarioFrom::Given(given), _, _) => given.clone(),
        (ScenarioFrom::Resumed, Some(resumed), _) => resumed.scenario_name()?,
        (ScenarioFrom::CasesFrom, _, Some(source)) => source.scenario_name()?,
        _ => DEFAULT_SCENARIO.to_owned(),
    };
    let loaded = load_scenario(&scenario_arg)?;
    print_warnings(&scenario_arg, &loaded);
    let scenario = loaded.scenario;
    if scenario.anchors.is_empty() && !args.allow_no_anchors {
        anyhow::bail!(
            "{}: the scenario has no anchors, so the car's UWB estimate would be dead reckoning \
             only and every test would say nothing about UWB positioning; add its anchors \
             (`scenario import --anchors`) or pass --allow-no-anchors",
            loaded.source
        );
    }
    let cars = named_cars(&args.car)?;
    // A campaign begun on several cars goes on as one on several cars, also with one car left:
    // its cars named, each credited with the tests it drove, one recording span per test.
    let on_several = cars.len() > 1
        || resumed.as_ref().is_some_and(|r| {
            !r.record.cars.is_empty()
                && !matches!(cars[0].address, CarAddress::Sim | CarAddress::Sitl { .. })
        });
    let car_label = cars_label(&cars, on_several);
    let address = cars[0].address.clone();
    // A fresh car for each test: the embedded simulated car, or the car's own firmware built
    // for the host (its physical car and world are the simulated car's).
    let firmware = match &address {
        CarAddress::Sitl { tree } => Some(super::firmware::build(tree)?),
        _ => None,
    };
    let embedded = address == CarAddress::Sim || firmware.is_some();
    if args.profile.is_some() && !embedded {
        anyhow::bail!(
            "--profile describes the embedded simulated car (--car sim) or the physical car \
             around the firmware built for the host (--car sitl:TREE), not the car at {car_label}"
        );
    }
    let profile = crate::profile_arg::load(args.profile.as_deref())?;
    let sim = profile.sim_config(&scenario)?;
    if let Some(resumed) = &resumed {
        let addresses: Vec<CarAddress> = cars.iter().map(|c| c.address.clone()).collect();
        let given = matches!(settings.scenario, ScenarioFrom::Given(_));
        resumed.check(
            args,
            &scenario,
            given,
            &profile,
            firmware.as_ref(),
            &addresses,
        )?;
    }
    let seed = choose_seed(settings.seed);
    let campaign = Campaign {
        seed,
        tests: settings.tests.unwrap_or(scenario.campaign.tests),
        no_faults: settings.no_faults,
    };
    let cases = source
        .map(|source| source.check(&scenario, &campaign))
        .transpose()?;
    let stale = &args.stale_after;
    if stale.value.is_zero() || stale.value > MAX_STALE_LIMIT {
        anyhow::bail!(
            "--stale-after {}: must be above 0 and at most {} (the car's watchdog brakes after {} \
             without commands)",
            stale.text,
            stale.in_typed_units(MAX_STALE_LIMIT),
            stale.in_typed_units(WATCHDOG),
        );
    }
    if args.dry_run {
        let mut found = Vec::new();
        for car in &cars {
            found.push(dry_run(
                args,
                car,
                firmware.as_ref(),
                &scenario,
                &sim,
                campaign,
                cases.clone(),
            )?);
        }
        if args.json {
            // One document: a car's findings, or with several cars each car's by name.
            match found.as_slice() {
                [one] => output::print_json(output::json::RUN_DRY_RUN, one)?,
                _ => {
                    #[derive(serde::Serialize)]
                    struct CarFound<'a> {
                        name: &'a str,
                        address: &'a str,
                        #[serde(flatten)]
                        found: &'a runner::DryRun,
                    }
                    let cars: Vec<CarFound<'_>> = cars
                        .iter()
                        .zip(&found)
                        .map(|(car, found)| CarFound {
                            name: &car.name,
                            address: &car.given,
                            found,
                        })
                        .collect();
                    output::print_json(
                        output::json::RUN_DRY_RUN,
                        &serde_json::json!({ "cars": cars }),
                    )?;
                }
            }
        }
        return Ok(Exit::Success);
    }
    let made = settings.out == OutDir::Default;
    let out = match &settings.out {
        OutDir::Resumed(dir) | OutDir::Given(dir) => dir.clone(),
        OutDir::Default => {
            let name = run_dir_name(&scenario.name, seed);
            runner::claim_default_run_dir(&match settings.shard {
                Some(shard) => format!("{name}-shard{}of{}", shard.index, shard.count),
                None => name,
            })?
        }
    };
    // A resumed campaign's directory is claimed again: not while another process writes it.
    let claim = match &settings.out {
        OutDir::Resumed(_) => runner::claim_run_dir_again(&out)?,
        _ => runner::claim_out_dir(&out, made)?,
    };
    if let Some(note) = claim.stale_note() {
        output::note(note);
    }
    // What a process killed while writing it left (`kill -9`: a temporary file of a case file
    // or of campaign.json) is nobody's: removed, with a note.
    super::signals::note_leftovers(runner::scratch::clear_leftovers(&out));
    if let Some(file) = &args.junit {
        super::case_input::check_output_file("--junit", file, &out)?;
    }
    let mut config = RunConfig::new(campaign, out, car_label.clone());
    config.safety.stale_after = args.stale_after.value;
    config.policy = settings.policy;
    config.tests = cases.map_or(Tests::Generated, |(cases, _)| Tests::Cases(cases));
    config.shard = settings.shard;
    config.record = match args.record {
        RecordArg::All => RecordMode::All,
        RecordArg::Failing => RecordMode::Failing,
        RecordArg::None => RecordMode::None,
    };
    if embedded {
        config.car_profile = Some(profile.clone());
    }
    config.car_firmware_tree_hash = firmware.as_ref().map(|f| f.tree_hash.clone());
    // Each failing test explained as it ends, in its worker (the embedded simulated car).
    config.explain = Some(report::explain::explain_held);
    let jobs = jobs(args, embedded, &car_label)?;
    // A live view is for watching: a virtual-time campaign would be over before anyone looks.
    let virtual_time = embedded && !args.realtime && args.live.is_none();
    if let Some(resumed) = resumed {
        output::note(resumed.describe());
        config.resume = Some(resumed.prepare(config.record != RecordMode::None)?);
    }
    output::note(format_args!(
        "seed {seed}: {}{} tests on {} with car{} {}{}{}, writing {}",
        config.test_indices().len(),
        config
            .shard
            .map(|s| format!(" of {} (shard {s})", campaign.tests))
            .unwrap_or_default(),
        scenario.name,
        if cars.len() > 1 { "s" } else { "" },
        car_label,
        if virtual_time { " (virtual time)" } else { "" },
        if jobs > 1 {
            format!(", {jobs} at once")
        } else {
            String::new()
        },
        config.out_dir.display()
    ));
    let started = Instant::now();
    let result = if let Some(firmware) = &firmware {
        let cars = runner::vehicle::sitl::SitlCars::new(
            firmware,
            &sim,
            config.campaign.seed,
            virtual_time,
        );
        campaign_on_fresh_cars(&cars, &scenario, &mut config, jobs, args.live)
    } else if embedded {
        let cars = EmbeddedSims::new(&sim, config.campaign.seed, virtual_time);
        campaign_on_fresh_cars(&cars, &scenario, &mut config, jobs, args.live)
    } else if on_several {
        let runtime = runtime(false)?;
        runtime.block_on(async {
            let names: Vec<&str> = cars.iter().map(|c| c.name.as_str()).collect();
            let _server = start_live(args.live, &names, false, &mut config).await?;
            campaign_on_cars(&cars, &scenario, &config).await
        })
    } else {
        let runtime = runtime(false)?;
        runtime.block_on(async {
            // The server lives until the campaign ends.
            let _server = start_live(args.live, &[], false, &mut config).await?;
            campaign_on(&address, &scenario, &config).await
        })
    };
    let wall = started.elapsed();
    let report = result?;
    if !args.json {
        print_report(&report, Some(wall));
    }
    explain_failed(&report, &scenario, !args.json);
    if let Some(file) = &args.junit {
        let clock = if virtual_time {
            junit::Clock::Simulated
        } else {
            junit::Clock::Wall
        };
        write_junit(&report, file, clock, Some(wall.as_secs_f64()))?;
    }
    if args.shrink {
        shrink_failed(
            &report,
            &scenario,
            (&sim, firmware.as_ref()),
            args.shrink_budget,
            !args.json,
        )?;
    }
    if args.report {
        let options = report::ReportOptions {
            all_tests: args.report_all_tests,
        };
        super::report::write(
            &report.dir,
            &report.dir.join(REPORT_FILE),
            Some(&scenario),
            &options,
        )?;
    }
    if args.json {
        super::table::print_report_json(output::json::RUN, &report, Some(wall))?;
    }
    let summary = report.record.summary.as_ref();
    // A shard may hold no test (more shards than tests): it ran all of its tests.
    let all_passed =
        summary.is_some_and(|s| s.passed == s.tests && (s.tests > 0 || settings.shard.is_some()));
    Ok(if all_passed {
        Exit::Success
    } else {
        Exit::Found
    })
}

/// `run --dry-run`: connects, runs preflight, uploads the first test's route and faults and reads
/// them back, clears them, and says what it found; the car does not move and nothing is written.
fn dry_run(
    args: &RunArgs,
    car: &NamedCar,
    firmware: Option<&runner::vehicle::sitl::HostFirmware>,
    scenario: &Scenario,
    sim: &car_sim::SimConfig,
    campaign: Campaign,
    cases: Option<(CasesSource, FailurePolicy)>,
) -> Result<runner::DryRun> {
    let address = &car.address;
    let mut config = RunConfig::new(campaign, std::path::PathBuf::new(), car.given.clone());
    config.safety.stale_after = args.stale_after.value;
    config.shard = args.shard;
    config.tests = cases.map_or(Tests::Generated, |(cases, _)| Tests::Cases(cases));
    async fn check<V: runner::vehicle::Vehicle>(
        connected: &V,
        given: &str,
        scenario: &Scenario,
        config: &RunConfig,
    ) -> Result<runner::DryRun> {
        output::progress(format_args!(
            "connected to {given} (firmware {}); preflight, then the first test's route and \
             faults uploaded and read back, with the autopilot off",
            connected.version()
        ));
        runner::dry_run(connected, scenario, config, &super::progress::WarningsOnly)
            .await
            .map_err(anyhow::Error::from)
    }
    let found = runtime(false)?.block_on(async {
        match firmware {
            Some(firmware) => {
                let sitl = runner::vehicle::sitl::SitlCar {
                    executable: firmware.executable.clone(),
                    plant: runner::vehicle::sitl::plant_options(firmware, sim),
                };
                let (connected, _running) = runner::vehicle::sitl::connect_sitl(&sitl).await?;
                check(&connected, &car.given, scenario, &config).await
            }
            None => {
                let (connected, _sim) = connect(address, sim, campaign.seed).await?;
                check(&connected, &car.given, scenario, &config).await
            }
        }
    })?;
    if !args.json {
        println!(
            "dry run passed: {}the car at {} is ready (nothing was driven, nothing written)",
            if args.car.len() > 1 {
                format!("car {}, ", car.name)
            } else {
                String::new()
            },
            car.given
        );
        println!("  firmware {}", found.firmware);
        if !found.switched_off.is_empty() {
            println!("  preflight switched off {}", found.switched_off.join(", "));
        }
        println!(
            "  round trip {:.1} ms median, {:.1} ms p99; stale-telemetry limit {:.0} ms",
            found.round_trip_ms[0], found.round_trip_ms[1], found.stale_after_ms
        );
        println!(
            "  {} route points uploaded and read back (largest difference {:.3}), then cleared",
            found.route_points, found.route_read_back_error
        );
        println!(
            "  {} fault commands uploaded, {} listed back, then cleared",
            found.faults_uploaded, found.faults_listed
        );
    }
    Ok(found)
}

/// Explains every failing segment and prints the first cause per segment (with `print`; else the
/// causes are only in the case files). A campaign on fresh simulated cars explained each failing
/// test as it ended ([`runner::ExplainHeld`]): its case files are read, a test at a time.
/// Otherwise (a real car, a resumed campaign's earlier tests) the recording is read
/// (`drivecheck explain`) and each case's `explanation` written. What cannot be explained (no
/// recording) is a warning: the campaign's results stand without it.
fn explain_failed(report: &CampaignReport, scenario: &Scenario, print: bool) {
    let failing: Vec<&runner::TestSummary> = report
        .tests
        .iter()
        .filter(|t| t.verdict == Some(Verdict::Failed))
        .collect();
    if failing.is_empty() {
        return;
    }
    // Every explanation is in its case file; a summary's share is printed.
    let shown = if print && output::verbosity() >= output::Verbosity::Normal {
        super::progress::listed_at_most()
    } else {
        0
    };
    let mut lines = Lines::new(shown);
    let mut explained_as_run = true;
    for test in &failing {
        match report.case(test) {
            Ok(case) if !case.explanation.is_empty() => lines.add_records(&case),
            _ => {
                explained_as_run = false;
                break;
            }
        }
    }
    if !explained_as_run {
        lines = Lines::new(shown);
        explain_from_recording(report, scenario, &mut lines);
    }
    lines.print();
}

/// The lines `run` prints of the failing segments' first causes: the first `shown`, and how many
/// more there are.
struct Lines {
    shown: usize,
    printed: Vec<String>,
    explained: usize,
}

impl Lines {
    fn new(shown: usize) -> Self {
        Self {
            shown,
            printed: Vec::new(),
            explained: 0,
        }
    }

    fn add(
        &mut self,
        test_index: usize,
        segment_index: usize,
        cause: String,
        share: f64,
        more: bool,
    ) {
        self.explained += 1;
        if self.printed.len() < self.shown {
            self.printed.push(format!(
                "why test {test_index:03} segment {segment_index} failed: {cause} ({:.0} % of the growth{})",
                share * 100.0,
                if more {
                    "; drivecheck explain for the rest"
                } else {
                    ""
                }
            ));
        }
    }

    /// The segments of a case file's `explanation`.
    fn add_records(&mut self, case: &Case) {
        for segment in &case.explanation {
            let Some(top) = segment.causes.first() else {
                continue;
            };
            self.add(
                case.test_index.unwrap_or_default(),
                segment.segment_index,
                describe(&top.source.into(), Some(case)),
                top.share,
                segment.causes.len() > 1,
            );
        }
    }

    fn print(&self) {
        for line in &self.printed {
            println!("{line}");
        }
        if self.explained > self.printed.len() && self.shown > 0 {
            println!(
                "… and {} more failing segments explained in their case files (drivecheck explain DIR; -v prints them all)",
                self.explained - self.printed.len()
            );
        }
    }
}

/// Explains the failing segments from the recording (`drivecheck explain`) and writes each
/// case's `explanation` into its case file.
fn explain_from_recording(report: &CampaignReport, scenario: &Scenario, lines: &mut Lines) {
    let explained = match explain_run(
        &report.dir,
        None,
        Some(scenario),
        &ExplainOptions::default(),
    ) {
        Ok(explained) => explained,
        Err(error) => {
            output::warning(format_args!("the failures are not explained: {error}"));
            return;
        }
    };
    for case in explained.cases.iter().filter(|c| !c.segments.is_empty()) {
        let written = std::fs::read_to_string(&case.case)
            .map_err(anyhow::Error::from)
            .and_then(|text| Ok(Case::from_json(&text)?))
            .and_then(|mut on_disk| {
                on_disk.explanation = case.segments.iter().map(Into::into).collect();
                runner::atomic::write(&case.case, format!("{}\n", on_disk.to_json()?))?;
                Ok(on_disk)
            });
        let on_disk = match written {
            Ok(on_disk) => Some(on_disk),
            Err(error) => {
                output::warning(format_args!(
                    "{}: the explanation is not written: {error}",
                    case.case.display()
                ));
                None
            }
        };
        for segment in &case.segments {
            let Some(top) = segment.causes.first() else {
                continue;
            };
            lines.add(
                case.test_index,
                segment.segment_index,
                describe(&top.source, on_disk.as_ref()),
                top.share,
                segment.causes.len() > 1,
            );
        }
    }
}

/// Writes the campaign's tests as JUnit XML to `file`; `clock` is whose seconds the cases hold,
/// `wall_s` how long the campaign took on the wall clock.
pub(super) fn write_junit(
    report: &CampaignReport,
    file: &std::path::Path,
    clock: junit::Clock,
    wall_s: Option<f64>,
) -> Result<()> {
    let record = &report.record;
    // A test's case file at a time: what JUnit says of it is kept, the case is not.
    let cases = report
        .tests
        .iter()
        .map(|test| {
            Ok(junit::TestCase {
                name: format!("seed-{}/test-{:03}", record.seed, test.test_index),
                case: (&report.case(test)?).into(),
                file: report.dir.join(&test.file).display().to_string(),
            })
        })
        .collect::<Result<Vec<_>, runner::RunError>>()?;
    let mut properties = vec![
        ("seed".to_owned(), record.seed.to_string()),
        ("scenario".to_owned(), record.scenario.name.clone()),
        ("car".to_owned(), record.car.clone()),
        ("tool_version".to_owned(), record.header.tool().to_owned()),
        ("no_faults".to_owned(), record.no_faults.to_string()),
        ("run_directory".to_owned(), report.dir.display().to_string()),
    ];
    if let Some(hash) = &record.scenario.hash {
        properties.push(("scenario_hash".to_owned(), hash.clone()));
    }
    if let Some(firmware) = &record.car_firmware_version {
        properties.push(("car_firmware_version".to_owned(), firmware.clone()));
    }
    let suite = junit::Suite {
        name: format!("campaign seed {} on {}", record.seed, record.scenario.name),
        classname: format!("drivecheck.{}", record.scenario.name),
        timestamp: record.started_at.clone(),
        properties,
        cases,
        clock,
        wall_s,
    };
    let xml = junit::to_xml(&[suite]).context("cannot write the JUnit XML")?;
    runner::atomic::write(file, xml).with_context(|| format!("cannot write {}", file.display()))?;
    output::note(format_args!("JUnit XML: {}", file.display()));
    Ok(())
}

/// Shrinks every failed test's case file into `shrink-NNN/` of the run directory and prints a
/// line per case (on standard output, or standard error when it is not `to_stdout`: `--json`); a
/// case that cannot be shrunk (it does not fail the same way every time in the simulator, say)
/// gets a warning and the next one is shrunk.
fn shrink_failed(
    report: &CampaignReport,
    scenario: &Scenario,
    (sim, firmware): (
        &car_sim::SimConfig,
        Option<&runner::vehicle::sitl::HostFirmware>,
    ),
    budget: Duration,
    to_stdout: bool,
) -> Result<()> {
    let failed: Vec<usize> = report
        .tests
        .iter()
        .filter(|t| t.verdict == Some(Verdict::Failed))
        .map(|t| t.test_index)
        .collect();
    if failed.is_empty() {
        return Ok(());
    }
    output::progress(format_args!("shrinking {} failed case(s)", failed.len()));
    let runtime = runtime(true)?;
    let mut lines = vec![
        "| case | commands | segments | faults | failing segment | simulator runs | wall |"
            .to_owned(),
        "|---|---|---|---|---|---|---|".to_owned(),
    ];
    for test_index in failed {
        let path = report.dir.join(format!("case-{test_index:03}.json"));
        let out = report.dir.join(format!("shrink-{test_index:03}"));
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let case = Case::from_json(&text).with_context(|| path.display().to_string())?;
        let options = shrink::Options {
            runs: 3,
            budget,
            seed: case.campaign_seed.unwrap_or(report.record.seed),
            margin: shrink::DEFAULT_MARGIN_M,
            sim: sim.clone(),
            firmware: firmware.cloned(),
        };
        let result = shrink::shrink_case(&runtime, &path, &case, scenario, &options, &out, true);
        match result {
            Ok(r) => lines.push(format!(
                "| {} | {} → {} | {} → {} | {} → {} | {} → {} | {} | {:.1} s |",
                out.join(MINIMAL_FILE).display(),
                r.before.size.commands,
                r.after.size.commands,
                r.before.size.segments,
                r.after.size.segments,
                r.before.size.faults,
                r.after.size.faults,
                r.before.target,
                r.after.target,
                r.simulator_runs,
                r.wall_s
            )),
            Err(error) => output::warning(format_args!("not shrunk: {error:#}")),
        }
    }
    if to_stdout {
        println!("{}", lines.join("\n"));
    } else {
        output::note(lines.join("\n"));
    }
    Ok(())
}

/// How many tests run at once: `--jobs`, by default the cores for the embedded simulated car
/// (one with a live view, which shows one car); a real car drives one test at a time.
fn jobs(args: &RunArgs, embedded: bool, car_label: &str) -> Result<usize> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    if let Some(n) = args.jobs.filter(|&n| n > 1 && args.car.len() > 1) {
        anyhow::bail!(
            "--jobs {n}: several cars drive their tests at once already, one test per car \
             ({car_label}); leave --jobs out"
        );
    }
    match (args.jobs, embedded, args.live) {
        (Some(n), false, _) if n > 1 => anyhow::bail!(
            "--jobs {n}: a real car (--car {car_label}) drives one test at a time; give several \
             cars (--car A=… --car B=…) to drive tests at once"
        ),
        (Some(n), true, Some(_)) if n > 1 => {
            anyhow::bail!("--jobs {n} with --live: the live view shows one car; use --jobs 1")
        }
        (Some(n), _, _) => Ok(n as usize),
        (None, true, None) => Ok(cores),
        (None, _, _) => Ok(1),
    }
}

/// Serves the live view when asked (`--live`) and sets it in `config`; the server's handle, which
/// serves until dropped. `cars` and `simulated`: which channels the view makes before a viewer
/// can connect (see [`LiveView::start`]).
async fn start_live(
    live: Option<std::net::SocketAddr>,
    cars: &[&str],
    simulated: bool,
    config: &mut RunConfig,
) -> Result<Option<recording::live::LiveServer>> {
    let Some(addr) = live else {
        return Ok(None);
    };
    let (view, server) = LiveView::start(addr, cars, simulated).await?;
    output::note(format_args!(
        "live view: ws://{}:{} (Foxglove: Open connection…)",
        addr.ip(),
        server.port()
    ));
    config.live = Some(view);
    Ok(Some(server))
}

/// Runs the campaign on the embedded simulator, a fresh simulated car per test, `jobs` at once,
/// interrupted by Ctrl-C.
fn campaign_on_fresh_cars<C: runner::vehicle::FreshCars>(
    cars: &C,
    scenario: &Scenario,
    config: &mut RunConfig,
    jobs: usize,
    live: Option<std::net::SocketAddr>,
) -> Result<CampaignReport> {
    // The signals and the live view's server run on a runtime of their own; every test runs on
    // its own runtime on a worker thread.
    let runtime = runtime(false)?;
    let _server = runtime.block_on(start_live(live, &[], true, config))?;
    let _context = runtime.enter();
    let interrupt = Interrupt::listen();
    let progress = Progress::new(config.test_indices().len());
    let result = run_campaign_fresh(cars, scenario, config, jobs, interrupt.token(), &progress);
    progress.finish();
    result
        .map_err(|failure| anyhow::Error::new(CampaignFailed::new(failure.error, &config.out_dir)))
}

/// Connects to the car and runs the campaign, interrupted by Ctrl-C.
async fn campaign_on(
    address: &CarAddress,
    scenario: &Scenario,
    config: &RunConfig,
) -> Result<CampaignReport, anyhow::Error> {
    let (car, sim) = connect(
        address,
        &car_sim::SimConfig::from_scenario(scenario),
        config.campaign.seed,
    )
    .await?;
    let interrupt = Interrupt::listen();
    let _brake = interrupt.brake_on_second(&car);
    let progress = Progress::new(config.campaign.tests);
    let result = run_campaign(
        &car,
        scenario,
        config,
        interrupt.token(),
        &progress,
        sim_view(&sim),
    )
    .await;
    progress.finish();
    result
        .map_err(|failure| anyhow::Error::new(CampaignFailed::new(failure.error, &config.out_dir)))
}

/// A car `--car` names.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct NamedCar {
    /// Its name (`A` of `A=tcp://…`; `car1`, `car2`, … in the order given).
    pub(super) name: String,
    /// Its address.
    pub(super) address: CarAddress,
    /// The address as given.
    pub(super) given: String,
}

/// The longest name of a car.
const MAX_CAR_NAME: usize = 32;

/// The cars of `--car` given `given` times: one car (any address), or several cars behind links,
/// each with a name of its own (`NAME=ADDRESS`, or `car<k>` by its place) and an address of its
/// own.
pub(super) fn named_cars(given: &[String]) -> Result<Vec<NamedCar>> {
    let mut cars: Vec<NamedCar> = Vec::new();
    for (k, text) in given.iter().enumerate() {
        // `NAME=` only when NAME is a name: an address may hold `=` (`serial://…?baud=…`).
        let (name, address_text) = match text.split_once('=') {
            Some((name, rest))
                if !name.is_empty()
                    && name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') =>
            {
                (name.to_owned(), rest)
            }
            _ => (format!("car{}", k + 1), text.as_str()),
        };
        if name.len() > MAX_CAR_NAME {
            anyhow::bail!(
                "--car {text}: the name {name:?} is longer than {MAX_CAR_NAME} characters"
            );
        }
        let address: CarAddress = address_text
            .parse()
            .with_context(|| format!("--car {text}"))?;
        if given.len() > 1 && matches!(address, CarAddress::Sim | CarAddress::Sitl { .. }) {
            anyhow::bail!(
                "--car {text}: the embedded simulated car gives every test a fresh car already; \
                 run its tests at once with --jobs N, and give several --car only for cars behind \
                 links (tcp://, udp://, serial://)"
            );
        }
        if let Some(other) = cars.iter().find(|c| c.name == name) {
            anyhow::bail!(
                "--car {text}: the name {name} is already the car at {}; name each car once",
                other.given
            );
        }
        if let Some(other) = cars.iter().find(|c| c.address == address) {
            anyhow::bail!(
                "--car {text}: the car at {address_text} is already car {}: a car drives one test at a time",
                other.name
            );
        }
        cars.push(NamedCar {
            name,
            address,
            given: address_text.to_owned(),
        });
    }
    if cars.is_empty() {
        anyhow::bail!("--car: no car given");
    }
    Ok(cars)
}

/// What `campaign.json` calls the cars: the address of one, `A=…, B=…` of several (and of one
/// that goes on with a campaign begun on several).
fn cars_label(cars: &[NamedCar], several: bool) -> String {
    match cars {
        [one] if !several => one.given.clone(),
        several => several
            .iter()
            .map(|c| format!("{}={}", c.name, c.given))
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// Connects to every car and runs the campaign on them together, interrupted by Ctrl-C. A car
/// that cannot be connected leaves before the campaign starts (named); with none left, the
/// campaign does not start.
async fn campaign_on_cars(
    cars: &[NamedCar],
    scenario: &Scenario,
    config: &RunConfig,
) -> Result<CampaignReport, anyhow::Error> {
    let sim = &car_sim::SimConfig::from_scenario(scenario);
    let connecting = cars
        .iter()
        .map(|car| async move { (car, connect(&car.address, sim, config.campaign.seed).await) });
    let mut connected = Vec::new();
    let mut unreachable = Vec::new();
    for (car, result) in futures::future::join_all(connecting).await {
        match result {
            Ok((vehicle, _)) => connected.push(runner::LabCar {
                name: car.name.clone(),
                address: car.given.clone(),
                car: vehicle,
            }),
            Err(error) => {
                unreachable.push(format!("car {}: {:#}", car.name, anyhow::Error::new(error)))
            }
        }
    }
    if connected.is_empty() {
        anyhow::bail!("no car could be connected: {}", unreachable.join("; "));
    }
    for text in &unreachable {
        output::warning(format_args!("{text}; the campaign goes on without it"));
    }
    let interrupt = Interrupt::listen();
    let vehicles: Vec<_> = connected.iter().map(|c| c.car.clone()).collect();
    let _brake = interrupt.brake_all_on_second(&vehicles);
    let progress = Progress::new(config.test_indices().len());
    let result =
        runner::run_campaign_on_cars(&connected, scenario, config, interrupt.token(), &progress)
            .await;
    progress.finish();
    result
        .map_err(|failure| anyhow::Error::new(CampaignFailed::new(failure.error, &config.out_dir)))
}
