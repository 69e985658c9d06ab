//! `drivecheck replay CASE.json`: a recorded (or hand-written) case driven again N times, each
//! after the same reset, each recorded like a campaign, then compared segment by segment.
//!
//! Every run is a one-test campaign in `run-K/` inside the replay directory (`campaign.json`
//! naming the case it replays, the case file, `campaign.mcap`). A case from a campaign is driven
//! as its own test (`runner::SameTest`): test *i* of its campaign seed, so the reset's and safe
//! stop's seeds are the campaign's and the case file is `case-NNN.json` of its index; on the
//! embedded simulated car every run gets a fresh simulator, the test's own car (the seed map's
//! `Simulator` seed of test *i*) standing where the campaign placed it, so in virtual time every
//! segment's largest deviation is the case's (`--vary-seed`, or `--times` above 1, drives the
//! seed map's other cars of that test, `Purpose::Rerun`). A hand-written case is test 0 of a
//! campaign of its own. A real car is connected once and reset before each run. The comparison
//! (`replay.json`, see [`campaign::replay`]) says what the runs drove and, for the case's own
//! test, whether they reproduced it; it is written and printed at the end, also when a run
//! ended the replay early.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use car_link::CarAddress;
use car_sim::SimHandle;
use scenarios::Scenario;
use trajgen::{Generator, Strategy};

use super::signals::{Interrupt, runtime};
use super::table::{CampaignFailed, metres};
use crate::cli::ReplayArgs;
use crate::exit::Exit;
use crate::output;
use crate::profile_arg::LoadedProfile;
use crate::settings::{CaseSettings, DrivenOn};
use campaign::drive::EARLIER_TOOL_POINTS_LEFT;
use campaign::files::{CASE_FAULT_PLACES_SINCE, CommandRecord};
use campaign::files::{Case, ReplayOf, ScenarioRef};
use campaign::model::{Campaign, TestPlan};
use campaign::oracle::Verdict;
use campaign::replay::{Comparison, Drove, REPLAY_FILE, ReplayRun};
use campaign::seed::{Purpose, derive};
use report::REPORT_FILE;
use runner::vehicle::{ConnectError, SimulatorView, Vehicle, connect, connect_fresh, placed};
use runner::{
    ReplaySource, RunConfig, TestSummary, Tests, rfc3339_now, run_campaign, run_dir_name,
};

/// Replays the case and prints the comparison. Exit status: 0 every run passed, 1 a run failed
/// or was aborted, 2 an error (the case refused, the link lost, interrupted, …).
pub fn replay(args: &ReplayArgs) -> Result<Exit> {
    let path = &args.case;
    let CaseSettings {
        case,
        scenario,
        seed,
        car,
        firmware,
        profile,
        sim,
    } = CaseSettings::load("replay", path, &args.drive, true)?;
    let unplaced = case
        .commands
        .iter()
        .filter(|c| matches!(c, CommandRecord::AddFault { at: None, .. }))
        .count();
    if unplaced > 0 && !args.no_faults {
        let why = if case.header.schema_version < CASE_FAULT_PLACES_SINCE {
            format!(
                "a version-{} case: the places of its faults are unknown",
                case.header.schema_version
            )
        } else {
            "no place given".to_owned()
        };
        output::warning(format_args!(
            "{}: {unplaced} fault(s) without a place ({why}); each is sent as the earlier tool \
             sent faults, once its segment's car has {EARLIER_TOOL_POINTS_LEFT} or fewer route \
             points left of it",
            path.display()
        ));
    }
    let generator = Generator::new(scenario.generator.generator_config(Strategy::Wedge))
        .context("the scenario's generator settings")?;
    let plan = case
        .replay_plan(&scenario, &generator, seed, args.no_faults, 0)
        .with_context(|| format!("{}: cannot be replayed", path.display()))?;
    let (address, embedded) = match car {
        DrivenOn::Link(address) => (address, false),
        _ => (CarAddress::Sim, true),
    };
    let other_profile = embedded && warn_other_profile(&case, path, &profile);
    let virtual_time = embedded && !args.realtime;
    let times = args.times.unwrap_or(if args.vary_seed || !virtual_time {
        3
    } else {
        1
    });
    // The case's own test in virtual time is the same every run: more runs mean other cars.
    let implied_vary = virtual_time && !args.vary_seed && times > 1;
    let vary = args.vary_seed || implied_vary;
    // The case's test in its campaign (the seeds of its reset, safe stop and car, its start),
    // with --seed's campaign seed when given.
    let test = runner::SameTest::of_case(&case, &scenario)
        .with_context(|| format!("{}: where its test started", path.display()))?
        .map(|test| runner::SameTest {
            campaign_seed: seed,
            ..test
        });
    let drove = if !embedded {
        Drove::RealCar
    } else if test.is_none() {
        Drove::OwnCampaign
    } else if vary {
        Drove::OtherCars
    } else if !virtual_time {
        Drove::WallClock
    } else if args.no_faults || Some(seed) != case.campaign_seed || other_profile {
        Drove::Altered
    } else {
        Drove::SameTest
    };
    let made = args.out.is_none();
    let out = match &args.out {
        Some(out) => out.clone(),
        None => runner::claim_default_run_dir(&run_dir_name(
            &format!("replay-{}", scenario.name),
            seed,
        ))?,
    };
    let of = ReplayOf {
        case: path.display().to_string(),
        campaign_seed: case.campaign_seed,
        test_index: case.test_index,
        verdict: case.verdict,
        no_faults: args.no_faults,
    };
    let what = match (test, drove) {
        (Some(t), Drove::OtherCars) => format!(
            "test {} of campaign seed {seed} on {times} other simulated car(s){}",
            t.test_index,
            if implied_vary {
                format!(" (--times {times} implies --vary-seed)")
            } else {
                String::new()
            }
        ),
        (Some(t), Drove::RealCar) => {
            format!("test {} of campaign seed {seed} on the car", t.test_index)
        }
        (Some(t), _) => format!(
            "test {} of campaign seed {seed} on its own simulated car from its start",
            t.test_index
        ),
        (None, _) => format!("seed {seed}{}", if vary { " + run − 1" } else { "" }),
    };
    output::progress(format_args!(
        "replaying {} {times} time(s) on {} with car {}{}{}: {what}, writing {}",
        path.display(),
        scenario.name,
        args.drive.car,
        if virtual_time { " (virtual time)" } else { "" },
        if args.no_faults {
            " without its faults"
        } else {
            ""
        },
        out.display()
    ));
    let claim = runner::claim_out_dir(&out, made)?;
    if let Some(note) = claim.stale_note() {
        output::note(note);
    }
    if let Some(file) = &args.junit {
        super::case_input::check_output_file("--junit", file, &out)?;
    }
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let started = Instant::now();
    let started_at = rfc3339_now();
    let job = Job {
        args,
        address: &address,
        firmware: firmware.as_ref(),
        scenario: &scenario,
        sim: &sim,
        profile: embedded.then(|| profile.clone()),
        plan: &plan,
        of: &of,
        seed,
        test,
        times,
        vary,
        out: &out,
        policy: case.settings.as_ref().map(|s| s.failure_policy),
    };
    let (runs, error) = runtime(virtual_time)?.block_on(job.run_all());
    // Nothing driven (the car could not be reached): nothing to compare or keep.
    let nothing_driven = runs.iter().all(|(r, case)| {
        case.is_none() && r.verdict.is_none() && !runner::is_used(&out.join(&r.dir))
    });
    let error = match error {
        Some(error) if nothing_driven => return Err(error),
        other => other,
    };
    let comparison = Comparison::new(&case, of.clone(), ScenarioRef::of(&scenario), &runs, drove);
    let file = out.join(REPLAY_FILE);
    runner::atomic::write(&file, format!("{}\n", comparison.to_json()?))
        .with_context(|| format!("cannot write {}", file.display()))?;
    if let Some(junit_file) = &args.junit {
        let clock = if virtual_time {
            runner::junit::Clock::Simulated
        } else {
            runner::junit::Clock::Wall
        };
        let timing = (started_at.as_str(), started.elapsed().as_secs_f64(), clock);
        let case_file = format!("case-{:03}.json", test.map_or(0, |t| t.test_index));
        write_junit(
            &runs,
            &of,
            &scenario,
            (&out, &case_file),
            timing,
            junit_file,
        )?;
    }
    if args.report {
        super::report::write(
            &out,
            &out.join(REPORT_FILE),
            Some(&scenario),
            &report::ReportOptions::default(),
        )?;
    }
    if args.json {
        output::print_json(
            output::json::REPLAY,
            &ReplayJson {
                dir: &out,
                wall_time_s: started.elapsed().as_secs_f64(),
                replay: &comparison,
            },
        )?;
    } else {
        print!("{}", comparison.table());
        if implied_vary {
            println!(
                "--times {times} on the embedded simulated car in virtual time implies \
                 --vary-seed: the case's own car gives the same figures every run"
            );
        }
        println!(
            "{:.1} s wall time; replay directory: {} ({REPLAY_FILE} written {})",
            started.elapsed().as_secs_f64(),
            out.display(),
            rfc3339_now()
        );
    }
    if let Some(error) = error {
        return Err(error);
    }
    let all_passed = comparison
        .runs
        .iter()
        .all(|r| r.verdict == Some(Verdict::Passed));
    Ok(if all_passed {
        Exit::Success
    } else {
        Exit::Found
    })
}

/// Warns when `case` was driven on a simulated car of another profile than `profile` (and says
/// so): its results then need not be reproduced.
fn warn_other_profile(case: &Case, path: &Path, profile: &LoadedProfile) -> bool {
    let Some(recorded) = &case.car_profile else {
        return false;
    };
    let hash = profile.profile.hash();
    if recorded.hash != hash {
        output::warning(format_args!(
            "{} was driven on car profile {} ({}…), this replay on {} ({}…): another simulated \
             car, its results need not reproduce",
            path.display(),
            recorded.name,
            &recorded.hash[..recorded.hash.len().min(12)],
            profile.name,
            &hash[..12]
        ));
        return true;
    }
    false
}

/// Everything the runs share.
struct Job<'a> {
    args: &'a ReplayArgs,
    address: &'a CarAddress,
    /// `--car sitl:TREE`: the firmware every run starts afresh.
    firmware: Option<&'a super::firmware::HostFirmware>,
    scenario: &'a Scenario,
    /// The embedded simulated car (the scenario's, with the profile applied).
    sim: &'a car_sim::SimConfig,
    /// What the runs record of the profile (on the embedded simulated car).
    profile: Option<LoadedProfile>,
    plan: &'a TestPlan,
    of: &'a ReplayOf,
    seed: u64,
    /// The case's test in its campaign (`None`: a hand-written case, each run test 0 of a
    /// campaign of its own).
    test: Option<runner::SameTest>,
    /// Runs.
    times: u32,
    /// Other simulated cars (`--vary-seed`, or implied by `--times`).
    vary: bool,
    out: &'a Path,
    policy: Option<campaign::oracle::FailurePolicy>,
}

impl Job<'_> {
    /// Drives every run; stops early at the first run that ended with an error (returned).
    async fn run_all(&self) -> (Vec<(ReplayRun, Option<Case>)>, Option<anyhow::Error>) {
        let interrupt = Interrupt::listen();
        // A real car is connected once; the simulated one is fresh for every run.
        let mut shared = None;
        let mut runs = Vec::new();
        let sim = placed(self.sim.clone(), self.test.and_then(|t| t.start));
        for k in 0..self.times {
            let (seed, sim_seed) = self.seeds(k);
            let dir = format!("run-{}", k + 1);
            let (case, result) = match self.firmware {
                Some(firmware) => {
                    let config = car_sim::SimConfig {
                        seed: sim_seed,
                        ..sim.clone()
                    };
                    match connect_fresh(&config, Some(firmware)).await {
                        Ok((car, view)) => {
                            self.run_one(&car, Some(view), seed, &dir, &interrupt).await
                        }
                        Err(error) => (None, Err(error.into())),
                    }
                }
                None => {
                    let connecting = connect(self.address, &sim, sim_seed);
                    match car_for_run(&mut shared, connecting).await {
                        Ok((car, sim)) => {
                            let view = sim.map(|s| Box::new(s) as Box<dyn SimulatorView + Send>);
                            self.run_one(&car, view, seed, &dir, &interrupt).await
                        }
                        Err(error) => (None, Err(error.into())),
                    }
                }
            };
            let run = ReplayRun {
                dir,
                seed,
                simulator_seed: (self.profile.is_some() && sim_seed != seed).then_some(sim_seed),
                verdict: case.as_ref().and_then(|c| c.verdict),
                reason: case.as_ref().and_then(|c| c.reason.clone()),
            };
            output::progress(format_args!(
                "run {}/{}: {}, worst deviation {}{}",
                k + 1,
                self.times,
                run.verdict.map_or("not run", Verdict::as_str),
                case.as_ref().map_or_else(|| "-".to_owned(), worst),
                run.reason
                    .as_deref()
                    .map_or_else(String::new, |r| format!(" ({r})"))
            ));
            runs.push((run, case));
            if let Err(error) = result {
                return (runs, Some(error));
            }
        }
        (runs, None)
    }

    /// Run `k`'s (from 0) campaign seed and simulated car's seed: the case's own test (its
    /// campaign's car, or with `vary` the seed map's other cars of that test,
    /// [`Purpose::Rerun`] k + 1), or a hand-written case's seed (with `vary` [`Purpose::Run`] k).
    fn seeds(&self, k: u32) -> (u64, u64) {
        match self.test {
            Some(test) => {
                let run = if self.vary { u64::from(k) + 1 } else { 0 };
                let car = Purpose::Rerun {
                    test_index: test.test_index,
                    run,
                };
                (test.campaign_seed, derive(test.campaign_seed, car))
            }
            None => {
                let seed = if self.vary {
                    derive(self.seed, Purpose::Run { run: u64::from(k) })
                } else {
                    self.seed
                };
                (seed, seed)
            }
        }
    }

    /// Drives run `dir` with `seed` on `car` (`sim` its simulator, shut down after the run): the
    /// case it wrote (if it got that far), and how it ended.
    async fn run_one<V: Vehicle>(
        &self,
        car: &V,
        sim: Option<Box<dyn SimulatorView + Send>>,
        seed: u64,
        dir: &str,
        interrupt: &Interrupt,
    ) -> (Option<Case>, Result<()>) {
        let mut config = RunConfig::new(
            Campaign {
                seed,
                tests: 1,
                no_faults: self.args.no_faults,
            },
            self.out.join(dir),
            self.args.drive.car.clone(),
        );
        config.car_profile = self.profile.clone();
        config.tests = Tests::Replay(ReplaySource {
            plan: self.plan.clone(),
            of: self.of.clone(),
            as_test: self.test.map(|t| t.test_index),
        });
        if let Some(policy) = self.policy {
            config.policy = policy;
        }
        let _brake = interrupt.brake_on_second(car);
        let result = run_campaign(
            car,
            self.scenario,
            &config,
            interrupt.token(),
            &super::progress::WarningsOnly,
            sim.as_deref().map(|s| s as &dyn SimulatorView),
        )
        .await;
        // The simulated car stops with its view.
        drop(sim);
        match result {
            Ok(report) => match report.cases().next().transpose() {
                Ok(case) => (case, Ok(())),
                Err(error) => (None, Err(error.into())),
            },
            Err(failure) => (
                // The campaign's error is the one to say; a case it wrote is kept if readable.
                failure
                    .report
                    .and_then(|r| r.cases().next().and_then(Result::ok)),
                Err(anyhow::Error::new(CampaignFailed::new(
                    failure.error,
                    &config.out_dir,
                ))),
            ),
        }
    }
}

/// The car of the next run: the real car connected before, if any, or the one `connecting`
/// gives (awaited only then); a real car is kept in `slot` for the runs after it, a simulated
/// one is fresh for every run.
async fn car_for_run<V: Vehicle>(
    slot: &mut Option<V>,
    connecting: impl Future<Output = Result<(V, Option<SimHandle>), ConnectError>>,
) -> Result<(V, Option<SimHandle>), ConnectError> {
    if let Some(car) = slot {
        return Ok((car.clone(), None));
    }
    let (car, sim) = connecting.await?;
    if sim.is_none() {
        *slot = Some(car.clone());
    }
    Ok((car, sim))
}

/// The worst deviation of a run, for messages.
fn worst(case: &Case) -> String {
    metres(TestSummary::of(0, String::new(), case).worst_deviation_m)
}

/// Writes the replay's runs as JUnit XML to `file`: one testcase per run that wrote a case.
/// `timing`: when the replay started, how long it took on the wall clock, and whose seconds
/// the cases hold.
fn write_junit(
    runs: &[(ReplayRun, Option<Case>)],
    of: &ReplayOf,
    scenario: &Scenario,
    (out, case_file): (&Path, &str),
    (started_at, wall_s, clock): (&str, f64, runner::junit::Clock),
    file: &Path,
) -> Result<()> {
    // The case replayed, as the campaign named it (`seed-7/test-003`), or its file's name.
    let replayed = match (of.campaign_seed, of.test_index) {
        (Some(seed), Some(test)) => format!("seed-{seed}/test-{test:03}"),
        _ => Path::new(&of.case)
            .file_stem()
            .map_or_else(|| of.case.clone(), |s| s.to_string_lossy().into_owned()),
    };
    let cases = runs
        .iter()
        .filter_map(|(run, case)| {
            case.as_ref().map(|case| runner::junit::TestCase {
                name: format!("{replayed}/{}", run.dir),
                case: case.into(),
                file: out.join(&run.dir).join(case_file).display().to_string(),
            })
        })
        .collect();
    let suite = runner::junit::Suite {
        name: format!("replay of {} on {}", of.case, scenario.name),
        classname: format!("drivecheck.{}", scenario.name),
        timestamp: started_at.to_owned(),
        properties: vec![
            ("case".to_owned(), of.case.clone()),
            ("scenario".to_owned(), scenario.name.clone()),
            ("scenario_hash".to_owned(), scenario.hash()),
            ("no_faults".to_owned(), of.no_faults.to_string()),
            (
                "tool_version".to_owned(),
                campaign::files::tool_version().to_owned(),
            ),
            ("replay_directory".to_owned(), out.display().to_string()),
        ],
        cases,
        clock,
        wall_s: Some(wall_s),
    };
    let xml = runner::junit::to_xml(&[suite]).context("cannot write the JUnit XML")?;
    runner::atomic::write(file, xml).with_context(|| format!("cannot write {}", file.display()))?;
    output::note(format_args!("JUnit XML: {}", file.display()));
    Ok(())
}

/// A replay's result as `--json` prints it (docs/json.md).
#[derive(serde::Serialize)]
pub(super) struct ReplayJson<'a> {
    /// The replay directory.
    pub(super) dir: &'a Path,
    /// The replay's wall time, seconds.
    pub(super) wall_time_s: f64,
    /// `replay.json`: the runs and the comparison of their segments.
    pub(super) replay: &'a Comparison,
}
