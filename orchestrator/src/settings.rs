//! A command's settings resolved once: what its flags, `--resume DIR`, `--cases-from DIR` and
//! the scenario's defaults each decide, in one place and unit-tested here, so that a command
//! body reads one resolved value instead of working the precedence out flag by flag.
//!
//! For `run` the rule is: a resumed campaign keeps its plan and settings (a flag that differs is
//! refused before, by [`crate::commands`]' resume check), an earlier run's cases
//! (`--cases-from`) give the number of tests, the seed and the failure policy unless a flag
//! names them, and otherwise the flags and the scenario's defaults decide.

use std::path::PathBuf;

use campaign::files::CampaignRecord;
use campaign::oracle::FailurePolicy;
use campaign::shard::Shard;

use crate::cli::{OnFailure, RunArgs};

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
