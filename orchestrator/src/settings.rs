//! A command's settings resolved once: what its flags, `--resume DIR`, `--cases-from DIR` and
//! the scenario's defaults each decide, in one place and unit-tested here, so that a command
//! body reads one resolved value instead of working the precedence out flag by flag.
//!
//! For a command that drives one case on fresh cars (`replay`, `shrink`, `sweep`:
//! [`CaseSettings`]) the rule is: `--scenario`, else the bundled scenario the case names, else the
//! recording beside it (the case's hash checked against it unless `--ignore-scenario-hash`);
//! `--seed`, else the case's campaign seed, else a drawn one; `--car` a simulated car (`sim`, or
//! `sitl:TREE` built for the host) or, for `replay` alone, a car behind a link, which `--profile`
//! (the embedded simulated car's) cannot describe.
//!
//! For `run` the rule is: a resumed campaign keeps its plan and settings (a flag that differs is
//! refused before, by [`crate::commands`]' resume check), an earlier run's cases
//! (`--cases-from`) give the number of tests, the seed and the failure policy unless a flag
//! names them, and otherwise the flags and the scenario's defaults decide.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use campaign::files::{CampaignRecord, Case};
use campaign::oracle::FailurePolicy;
use campaign::shard::Shard;

use crate::cli::{CaseCarArgs, OnFailure, RunArgs};
use crate::commands::case_input::{check_hash, read_case, scenario_of};
use crate::commands::firmware::{self, HostFirmware};
use crate::profile_arg::LoadedProfile;

/// The car a case is driven on, resolved from `--car` and `--profile`.
#[derive(Debug, Clone, PartialEq)]
pub enum DrivenOn {
    /// The embedded simulated car.
    Embedded,
    /// The car's own firmware tree, to build for the host.
    Firmware(String),
    /// A car behind a link (`replay` only): `--profile` cannot describe it.
    Link(car_link::CarAddress),
}

impl DrivenOn {
    /// Resolves `--car` of `command`, given `--profile` or not, for a command that drives a car
    /// behind a link too or not (see the module doc for the rule).
    pub fn resolve(command: &str, car: &str, profile: bool, links: bool) -> Result<Self> {
        let address: car_link::CarAddress = car.parse().with_context(|| format!("--car {car}"))?;
        Ok(match address {
            car_link::CarAddress::Sim => Self::Embedded,
            car_link::CarAddress::Sitl { tree } => Self::Firmware(tree),
            _ if !links => bail!(
                "--car {car}: {command} drives the case on a fresh simulated car for every run: \
                 `sim` (the embedded simulated car) or `sitl:TREE` (the car's own firmware built \
                 for the host); drive a car behind a link with `drivecheck replay --car {car}`"
            ),
            _ if profile => bail!(
                "--profile describes the embedded simulated car (--car sim) or the physical car \
                 around the firmware built for the host (--car sitl:TREE), not the car at {car}"
            ),
            address => Self::Link(address),
        })
    }
}

/// The campaign seed a case is driven with: `--seed`, else the case's, else a drawn one.
pub fn case_seed(given: Option<u64>, recorded: Option<u64>) -> u64 {
    given
        .or(recorded)
        .unwrap_or_else(|| crate::seed::choose_seed(None))
}

/// A case-driving command's settings, resolved and loaded once.
pub struct CaseSettings {
    /// The case, read.
    pub case: Case,
    /// Its scenario (the hash checked).
    pub scenario: scenarios::Scenario,
    /// The campaign seed.
    pub seed: u64,
    /// The car.
    pub car: DrivenOn,
    /// `--car sitl:TREE`, built (or taken from the cache).
    pub firmware: Option<HostFirmware>,
    /// The car profile of a simulated car.
    pub profile: LoadedProfile,
    /// The embedded simulated car: the scenario's, with the profile applied.
    pub sim: car_sim::SimConfig,
}

impl CaseSettings {
    /// Reads the case at `path` and loads what `args` name for `command` (which drives a car
    /// behind a link too when `links`), in the order a user's mistakes are best told: the case,
    /// its scenario, the car and the profile, and only then a firmware build.
    pub fn load(command: &str, path: &Path, args: &CaseCarArgs, links: bool) -> Result<Self> {
        let case = read_case(path)?;
        let scenario = scenario_of(args.scenario.as_deref(), path, &case)?;
        check_hash(&case, &scenario, args.ignore_scenario_hash)?;
        let seed = case_seed(args.seed, case.campaign_seed);
        let car = DrivenOn::resolve(command, &args.car, args.profile.is_some(), links)?;
        let profile = crate::profile_arg::load(args.profile.as_deref())?;
        let sim = profile.sim_config(&scenario)?;
        let firmware = match &car {
            DrivenOn::Firmware(tree) => Some(firmware::build(tree)?),
            _ => None,
        };
        Ok(Self {
            case,
            scenario,
            seed,
            car,
            firmware,
            profile,
            sim,
        })
    }
}

/// What a campaign's plan and settings come from besides its flags.
#[derive(Debug, Clone, PartialEq)]
pub enum Origin {
    /// A campaign of its own.
    Fresh,
    /// `--cases-from DIR`: the earlier run's record and its number of cases.
    CasesFrom {
        /// What the earlier run recorded.
        recorded: Recorded,
        /// Its case files.
        cases: usize,
    },
    /// `--resume DIR`: the interrupted campaign's record, in its directory.
    Resumed {
        /// What the campaign recorded.
        recorded: Recorded,
        /// Its run directory.
        dir: PathBuf,
    },
}

/// What a campaign record says of the settings [`RunSettings`] resolves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Recorded {
    /// The campaign seed.
    pub seed: u64,
    /// The number of tests.
    pub tests: usize,
    /// Whether its tests had no faults.
    pub no_faults: bool,
    /// The failure policy.
    pub policy: FailurePolicy,
    /// Its shard.
    pub shard: Option<Shard>,
}

impl From<&CampaignRecord> for Recorded {
    fn from(record: &CampaignRecord) -> Self {
        Self {
            seed: record.seed,
            tests: record.settings.tests,
            no_faults: record.no_faults,
            policy: record.settings.failure_policy,
            shard: record.shard,
        }
    }
}

/// Which scenario a campaign loads.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScenarioFrom {
    /// `--scenario`.
    Given(String),
    /// The bundled scenario the resumed campaign names.
    Resumed,
    /// The bundled scenario the earlier run of `--cases-from` names.
    CasesFrom,
    /// The default scenario.
    Default,
}

/// Where a campaign's run directory is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutDir {
    /// The resumed campaign's own (claimed again).
    Resumed(PathBuf),
    /// `--out DIR` (created, or an empty one taken).
    Given(PathBuf),
    /// A new directory under the runs directory, named after the scenario and seed.
    Default,
}

/// `run`'s settings, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSettings {
    /// The scenario to load.
    pub scenario: ScenarioFrom,
    /// The campaign seed; `None`: draw one.
    pub seed: Option<u64>,
    /// The number of tests; `None`: the scenario's.
    pub tests: Option<usize>,
    /// Tests without faults.
    pub no_faults: bool,
    /// After a failing segment.
    pub policy: FailurePolicy,
    /// The shard run.
    pub shard: Option<Shard>,
    /// The run directory.
    pub out: OutDir,
}

impl RunSettings {
    /// Resolves `args` against `origin` (see the module doc for the rule).
    pub fn resolve(args: &RunArgs, origin: &Origin) -> Self {
        let given_policy = args.on_failure.map(|given| match given {
            OnFailure::Stop => FailurePolicy::StopAtFailingSegment,
            OnFailure::Continue => FailurePolicy::ContinueAndRecord,
        });
        let scenario = match (&args.scenario, origin) {
            (Some(given), _) => ScenarioFrom::Given(given.clone()),
            (None, Origin::Resumed { .. }) => ScenarioFrom::Resumed,
            (None, Origin::CasesFrom { .. }) => ScenarioFrom::CasesFrom,
            (None, Origin::Fresh) => ScenarioFrom::Default,
        };
        match origin {
            Origin::Resumed { recorded, dir } => Self {
                scenario,
                seed: Some(recorded.seed),
                tests: Some(recorded.tests),
                no_faults: recorded.no_faults,
                policy: given_policy.unwrap_or(recorded.policy),
                shard: recorded.shard,
                out: OutDir::Resumed(dir.clone()),
            },
            Origin::CasesFrom { recorded, cases } => Self {
                scenario,
                seed: Some(args.seed.unwrap_or(recorded.seed)),
                tests: Some(*cases),
                no_faults: args.no_faults,
                policy: given_policy.unwrap_or(recorded.policy),
                shard: args.shard,
                out: out_dir(args),
            },
            Origin::Fresh => Self {
                scenario,
                seed: args.seed,
                tests: args.tests,
                no_faults: args.no_faults,
                policy: given_policy.unwrap_or_default(),
                shard: args.shard,
                out: out_dir(args),
            },
        }
    }
}

fn out_dir(args: &RunArgs) -> OutDir {
    match &args.out {
        Some(out) => OutDir::Given(out.clone()),
        None => OutDir::Default,
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Debug, Parser)]
    struct Run {
        #[command(flatten)]
        run: RunArgs,
    }

    fn args(flags: &[&str]) -> RunArgs {
        Run::try_parse_from(std::iter::once("run").chain(flags.iter().copied()))
            .unwrap()
            .run
    }

    #[test]
    fn a_case_is_driven_on_a_simulated_car_and_only_replay_drives_one_behind_a_link() {
        let resolve = |car, profile, links| DrivenOn::resolve("shrink", car, profile, links);
        for links in [false, true] {
            let car = |c| resolve(c, true, links).unwrap();
            assert_eq!(car("sim"), DrivenOn::Embedded);
            assert_eq!(car("sitl:fw/RC"), DrivenOn::Firmware("fw/RC".into()));
        }
        let refused = resolve("tcp://car:8300", false, false).unwrap_err();
        assert!(
            refused
                .to_string()
                .contains("shrink drives the case on a fresh simulated car")
        );
        let link = resolve("tcp://car:8300", false, true).unwrap();
        assert!(matches!(
            link,
            DrivenOn::Link(car_link::CarAddress::Tcp { port: 8300, .. })
        ));
        // A profile describes a simulated car, never the car behind a link.
        let refused = resolve("tcp://car:8300", true, true).unwrap_err();
        assert!(
            refused
                .to_string()
                .starts_with("--profile describes the embedded")
        );
        let bad = resolve("carrier-pigeon", false, true).unwrap_err();
        assert!(bad.to_string().starts_with("--car carrier-pigeon"));
    }

    #[test]
    fn a_cases_seed_is_the_flags_else_the_cases_own_else_a_drawn_one() {
        assert_eq!(case_seed(Some(3), Some(7)), 3);
        assert_eq!(case_seed(None, Some(7)), 7);
        assert_eq!(case_seed(Some(3), None), 3);
        let drawn: std::collections::BTreeSet<u64> =
            (0..4).map(|_| case_seed(None, None)).collect();
        assert!(drawn.len() > 1, "drawn afresh each time: {drawn:?}");
    }

    fn recorded() -> Recorded {
        Recorded {
            seed: 7,
            tests: 30,
            no_faults: true,
            policy: FailurePolicy::ContinueAndRecord,
            shard: Some("2/3".parse().unwrap()),
        }
    }

    #[test]
    fn a_campaign_of_its_own_takes_its_flags_and_leaves_the_rest_to_the_scenario() {
        let s = RunSettings::resolve(&args(&[]), &Origin::Fresh);
        assert_eq!(
            s,
            RunSettings {
                scenario: ScenarioFrom::Default,
                seed: None,
                tests: None,
                no_faults: false,
                policy: FailurePolicy::StopAtFailingSegment,
                shard: None,
                out: OutDir::Default,
            }
        );
        let s = RunSettings::resolve(
            &args(&[
                "--scenario",
                "courtyard",
                "--seed",
                "4",
                "--tests",
                "9",
                "--no-faults",
                "--on-failure",
                "continue",
                "--shard",
                "1/2",
                "--out",
                "runs/x",
            ]),
            &Origin::Fresh,
        );
        assert_eq!(s.scenario, ScenarioFrom::Given("courtyard".into()));
        assert_eq!((s.seed, s.tests, s.no_faults), (Some(4), Some(9), true));
        assert_eq!(s.policy, FailurePolicy::ContinueAndRecord);
        assert_eq!(s.shard, Some("1/2".parse().unwrap()));
        assert_eq!(s.out, OutDir::Given("runs/x".into()));
    }

    #[test]
    fn a_resumed_campaign_keeps_its_plan_and_settings() {
        let origin = Origin::Resumed {
            recorded: recorded(),
            dir: "runs/cut".into(),
        };
        let s = RunSettings::resolve(&args(&[]), &origin);
        assert_eq!(
            s,
            RunSettings {
                scenario: ScenarioFrom::Resumed,
                seed: Some(7),
                tests: Some(30),
                no_faults: true,
                policy: FailurePolicy::ContinueAndRecord,
                shard: Some("2/3".parse().unwrap()),
                out: OutDir::Resumed("runs/cut".into()),
            }
        );
        // A flag that agrees is no change; `--no-faults` missing does not add the faults back.
        let s = RunSettings::resolve(&args(&["--on-failure", "continue"]), &origin);
        assert_eq!(
            (s.policy, s.no_faults),
            (FailurePolicy::ContinueAndRecord, true)
        );
        let s = RunSettings::resolve(&args(&["--scenario", "courtyard"]), &origin);
        assert_eq!(s.scenario, ScenarioFrom::Given("courtyard".into()));
    }

    #[test]
    fn an_earlier_runs_cases_give_the_tests_the_seed_and_the_policy_unless_a_flag_names_them() {
        let origin = Origin::CasesFrom {
            recorded: recorded(),
            cases: 12,
        };
        let s = RunSettings::resolve(&args(&[]), &origin);
        assert_eq!(s.scenario, ScenarioFrom::CasesFrom);
        assert_eq!((s.seed, s.tests), (Some(7), Some(12)));
        assert_eq!(s.policy, FailurePolicy::ContinueAndRecord);
        // Not the earlier run's shard or fault setting: those are this run's own.
        assert_eq!((s.shard, s.no_faults), (None, false));
        assert_eq!(s.out, OutDir::Default);
        let s = RunSettings::resolve(
            &args(&["--seed", "3", "--on-failure", "stop", "--no-faults"]),
            &origin,
        );
        assert_eq!((s.seed, s.tests, s.no_faults), (Some(3), Some(12), true));
        assert_eq!(s.policy, FailurePolicy::StopAtFailingSegment);
    }
}
